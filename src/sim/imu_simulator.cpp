#include "hanzo/fusion/sim/imu_simulator.hpp"

#include <cmath>

namespace hanzo::fusion::sim {


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

ImuSimulator::ImuSimulator(ImuSimulatorConfig config)
    : config_(std::move(config)), random_(config_.seed), accel_bias_(config_.initial_accel_bias), gyro_bias_(config_.initial_gyro_bias) {}

Eigen::Vector3d ImuSimulator::noise(double sigma) {
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::Vector3d draw = Eigen::Vector3d::Zero();
  for (int axis = 0; axis < 3; ++axis) draw[axis] = normal(random_) * sigma;  // drawn x, y, z in order
  return draw;
}

ImuSample ImuSimulator::measure(const SplineTrajectory& trajectory, Timestamp time) {
  if (previous_time_ && time > *previous_time_) {
    const double dt = (time - *previous_time_).seconds();
    accel_bias_ += noise(config_.accel_bias_random_walk * std::sqrt(dt));
    gyro_bias_ += noise(config_.gyro_bias_random_walk * std::sqrt(dt));
  }
  previous_time_ = time;
  Eigen::Vector3d specific_force = Eigen::Vector3d::Zero(), angular_rate = Eigen::Vector3d::Zero();
  ideal_measurement(trajectory, time, config_, specific_force, angular_rate);
  ImuSample sample;
  sample.accel_bias = accel_bias_;
  sample.gyro_bias = gyro_bias_;
  sample.message.timestamp = time;
  sample.message.frame_id = config_.frame_id;
  sample.message.linear_acceleration = specific_force + accel_bias_ + noise(config_.process_noise_accel);
  sample.message.angular_velocity = config_.gyro_scale_factor.cwiseProduct(angular_rate) + gyro_bias_ + noise(config_.process_noise_gyro);
  const double accel_variance = config_.process_noise_accel * config_.process_noise_accel;
  const double gyro_variance = config_.process_noise_gyro * config_.process_noise_gyro;
  if (accel_variance > 0) sample.message.acceleration_covariance = Eigen::Matrix3d::Identity() * accel_variance;
  if (gyro_variance > 0) sample.message.gyroscope_covariance = Eigen::Matrix3d::Identity() * gyro_variance;
  return sample;
}

std::vector<ImuSample> ImuSimulator::simulate(const SplineTrajectory& trajectory) {
  const double dt = 1.0 / config_.rate_hz;
  const auto count = static_cast<std::size_t>(std::floor((trajectory.end_time() - trajectory.start_time()).seconds() * config_.rate_hz)) + 1;
  std::vector<ImuSample> samples;
  samples.reserve(count);
  for (std::size_t k = 0; k < count; ++k) {
    samples.push_back(measure(trajectory, trajectory.start_time() + Duration::from_nanoseconds(std::llround(static_cast<double>(k) * dt * 1e9))));
  }
  return samples;
}

}  // namespace hanzo::fusion::sim
