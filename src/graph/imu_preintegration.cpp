#include "hanzo/fusion/graph/imu_preintegration.hpp"

#include <fmt/format.h>

namespace hanzo::fusion::graph {

ImuPreintegration::ImuPreintegration(const ImuPreintegrationConfig& config, const ImuBias& bias_estimate)
    : config_(config), bias_estimate_(bias_estimate) {}

Status ImuPreintegration::integrate(const Eigen::Vector3d& specific_force, const Eigen::Vector3d& angular_velocity, double dt) {
  if (!specific_force.allFinite() || !angular_velocity.allFinite()) return Error("imu preintegration: non-finite IMU sample");
  if (!(dt > 0.0 && dt <= 1.0)) return Error(fmt::format("imu preintegration: sample interval must be in (0, 1] s, got {}", dt));

  const Eigen::Vector3d acceleration = specific_force - bias_estimate_.accelerometer;
  const Eigen::Vector3d rotation_vector = (angular_velocity - bias_estimate_.gyroscope) * dt;
  Eigen::Matrix3d Jr;
  const SO3 step_rotation = SO3::exp(rotation_vector, &Jr);
  const Eigen::Matrix3d dR = deltas_.rotation.matrix();
  const Eigen::Matrix3d dR_acceleration_hat = dR * SO3::hat(acceleration);
  const Eigen::Matrix3d step_transpose = step_rotation.matrix().transpose();
  const double dt2 = dt * dt;

  // Noise propagation (eq. 62-63), order (rotation, velocity, position).
  Matrix9d A = Matrix9d::Identity();
  A.block<3, 3>(0, 0) = step_transpose;
  A.block<3, 3>(3, 0) = -dR_acceleration_hat * dt;
  A.block<3, 3>(6, 0) = -0.5 * dR_acceleration_hat * dt2;
  A.block<3, 3>(6, 3) = Eigen::Matrix3d::Identity() * dt;
  Eigen::Matrix<double, 9, 3> B = Eigen::Matrix<double, 9, 3>::Zero();
  B.block<3, 3>(3, 0) = dR * dt;
  B.block<3, 3>(6, 0) = 0.5 * dR * dt2;
  Eigen::Matrix<double, 9, 3> C = Eigen::Matrix<double, 9, 3>::Zero();
  C.block<3, 3>(0, 0) = Jr * dt;
  const double accel_variance = config_.process_noise_accel * config_.process_noise_accel * config_.sample_interval / dt;
  const double gyro_variance = config_.process_noise_gyro * config_.process_noise_gyro * config_.sample_interval / dt;
  covariance_ = A * covariance_ * A.transpose() + accel_variance * B * B.transpose() + gyro_variance * C * C.transpose();

  // Bias Jacobians (appendix, eq. 69-70), each from the values before this step.
  position_by_accel_bias_ += velocity_by_accel_bias_ * dt - 0.5 * dR * dt2;
  position_by_gyro_bias_ += velocity_by_gyro_bias_ * dt - 0.5 * dR_acceleration_hat * rotation_by_gyro_bias_ * dt2;
  velocity_by_accel_bias_ -= dR * dt;
  velocity_by_gyro_bias_ -= dR_acceleration_hat * rotation_by_gyro_bias_ * dt;
  rotation_by_gyro_bias_ = step_transpose * rotation_by_gyro_bias_ - Jr * dt;

  // Deltas (eq. 33-35).
  const Eigen::Vector3d rotated_acceleration = dR * acceleration;
  deltas_.position += deltas_.velocity * dt + 0.5 * rotated_acceleration * dt2;
  deltas_.velocity += rotated_acceleration * dt;
  deltas_.rotation = deltas_.rotation * step_rotation;
  delta_time_ += dt;
  ++sample_count_;
  return ok_status();
}

ImuDeltas ImuPreintegration::corrected(const ImuBias& bias) const {
  const Eigen::Vector3d accel_change = bias.accelerometer - bias_estimate_.accelerometer;
  const Eigen::Vector3d gyro_change = bias.gyroscope - bias_estimate_.gyroscope;
  ImuDeltas result;
  result.rotation = deltas_.rotation * SO3::exp(rotation_by_gyro_bias_ * gyro_change);
  result.velocity = deltas_.velocity + velocity_by_accel_bias_ * accel_change + velocity_by_gyro_bias_ * gyro_change;
  result.position = deltas_.position + position_by_accel_bias_ * accel_change + position_by_gyro_bias_ * gyro_change;
  return result;
}

void ImuPreintegration::predict(const SE3& T_world_i, const Eigen::Vector3d& velocity_i, const ImuBias& bias, SE3* T_world_j,
                                Eigen::Vector3d* velocity_j) const {
  const ImuDeltas delta = corrected(bias);
  const SO3& R_i = T_world_i.rotation();
  const double T = delta_time_;
  *T_world_j = SE3(R_i * delta.rotation,
                   T_world_i.translation() + velocity_i * T + 0.5 * config_.gravity * T * T + R_i * delta.position);
  *velocity_j = velocity_i + config_.gravity * T + R_i * delta.velocity;
}

}  // namespace hanzo::fusion::graph
