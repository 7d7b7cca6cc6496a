#include "hanzo/fusion/sim/imu_simulator.hpp"

#include <cmath>

namespace hanzo::fusion::sim {

ImuSimulator::ImuSimulator(ImuSimulatorConfig config) : config_(std::move(config)), random_(config_.seed) {}

void ImuSimulator::ideal_measurement(const SplineTrajectory& trajectory, Timestamp time, const ImuSimulatorConfig& config,
                                     Eigen::Vector3d& specific_force, Eigen::Vector3d& angular_rate) {
  const TrajectorySample body = trajectory.sample(time);
  const SO3& R_world_body = body.T_world_body.rotation();
  const Eigen::Vector3d& omega = body.angular_velocity_body;
  const Eigen::Vector3d& r = config.T_body_imu.translation();  // lever arm, body frame
  Eigen::Vector3d acceleration_body = R_world_body.inverse() * body.acceleration_world;
  if (r.squaredNorm() > 0.0) {
    const Duration h = Duration::from_milliseconds(1);
    const Eigen::Vector3d alpha = (trajectory.sample(time + h).angular_velocity_body -
                                   trajectory.sample(time - h).angular_velocity_body) / (2.0 * h.seconds());
    acceleration_body += alpha.cross(r) + omega.cross(omega.cross(r));
  }
  const Eigen::Vector3d gravity_body = R_world_body.inverse() * Eigen::Vector3d(0.0, 0.0, -config.gravity);
  const SO3 R_imu_body = config.T_body_imu.rotation().inverse();
  specific_force = R_imu_body * (acceleration_body - gravity_body);
  angular_rate = R_imu_body * omega;
}

std::vector<ImuSample> ImuSimulator::simulate(const SplineTrajectory& trajectory) {
  std::normal_distribution<double> normal(0.0, 1.0);
  auto noise = [&](double sigma) {
    Eigen::Vector3d draw = Eigen::Vector3d::Zero();
    for (int axis = 0; axis < 3; ++axis) draw[axis] = normal(random_) * sigma;  // drawn x, y, z in order
    return draw;
  };
  const double dt = 1.0 / config_.rate_hz;
  const auto count = static_cast<std::size_t>(std::floor((trajectory.end_time() - trajectory.start_time()).seconds() * config_.rate_hz)) + 1;
  Eigen::Vector3d accel_bias = config_.initial_accel_bias, gyro_bias = config_.initial_gyro_bias;
  const Eigen::Matrix3d accel_covariance = Eigen::Matrix3d::Identity() * config_.process_noise_accel * config_.process_noise_accel;
  const Eigen::Matrix3d gyro_covariance = Eigen::Matrix3d::Identity() * config_.process_noise_gyro * config_.process_noise_gyro;
  std::vector<ImuSample> samples;
  samples.reserve(count);
  for (std::size_t k = 0; k < count; ++k) {
    const Timestamp time = trajectory.start_time() + Duration::from_nanoseconds(std::llround(static_cast<double>(k) * dt * 1e9));
    Eigen::Vector3d specific_force = Eigen::Vector3d::Zero(), angular_rate = Eigen::Vector3d::Zero();
    ideal_measurement(trajectory, time, config_, specific_force, angular_rate);
    ImuSample sample;
    sample.accel_bias = accel_bias;
    sample.gyro_bias = gyro_bias;
    sample.message.timestamp = time;
    sample.message.frame_id = config_.frame_id;
    sample.message.linear_acceleration = specific_force + accel_bias + noise(config_.process_noise_accel);
    sample.message.angular_velocity = angular_rate + gyro_bias + noise(config_.process_noise_gyro);
    if (config_.process_noise_accel > 0) sample.message.acceleration_covariance = accel_covariance;
    if (config_.process_noise_gyro > 0) sample.message.gyroscope_covariance = gyro_covariance;
    samples.push_back(std::move(sample));
    accel_bias += noise(config_.accel_bias_random_walk * std::sqrt(dt));
    gyro_bias += noise(config_.gyro_bias_random_walk * std::sqrt(dt));
  }
  return samples;
}

}  // namespace hanzo::fusion::sim
