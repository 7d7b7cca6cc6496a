#include "hanzo/fusion/estimate/static_alignment.hpp"

#include <cmath>

#include <fmt/format.h>

namespace hanzo::fusion::estimate {

SO3 rotation_from_roll_pitch_yaw(double roll, double pitch, double yaw) {
  return SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), yaw) * SO3::from_axis_angle(Eigen::Vector3d::UnitY(), pitch) *
         SO3::from_axis_angle(Eigen::Vector3d::UnitX(), roll);
}

Result<StaticAlignment> align_static(const std::vector<ImuSample>& samples, const ImuMounting& mounting, double yaw,
                                     const StaticAlignmentConfig& config) {
  if (static_cast<int>(samples.size()) < config.min_samples) {
    return Error(fmt::format("static alignment needs at least {} IMU samples, got {}", config.min_samples, samples.size()));
  }
  // Means over motion_window_s windows: vibration (rotors, an idling engine) averages out, motion
  // (a push, a turn) does not.
  std::vector<ImuSample> windows;
  std::vector<int> window_counts;
  for (const ImuSample& sample : samples) {
    if (windows.empty() || (sample.timestamp - windows.back().timestamp).seconds() >= config.motion_window_s) {
      windows.push_back({sample.timestamp, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero()});
      window_counts.push_back(0);
    }
    windows.back().angular_velocity += sample.angular_velocity;
    windows.back().linear_acceleration += sample.linear_acceleration;
    ++window_counts.back();
  }
  if (windows.size() < 3) {  // too short a span to average: every sample is a window
    windows = samples;
    window_counts.assign(samples.size(), 1);
  }
  Eigen::Vector3d accel_mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_mean = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < windows.size(); ++i) {
    accel_mean += windows[i].linear_acceleration;
    gyro_mean += windows[i].angular_velocity;
    windows[i].linear_acceleration /= window_counts[i];
    windows[i].angular_velocity /= window_counts[i];
  }
  const double count = static_cast<double>(samples.size());
  accel_mean /= count;
  gyro_mean /= count;
  Eigen::Vector3d accel_variance = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_variance = Eigen::Vector3d::Zero();
  for (const ImuSample& window : windows) {
    accel_variance += (window.linear_acceleration - accel_mean).cwiseAbs2();
    gyro_variance += (window.angular_velocity - gyro_mean).cwiseAbs2();
  }
  const double accel_std = std::sqrt(accel_variance.maxCoeff() / static_cast<double>(windows.size()));
  const double gyro_std = std::sqrt(gyro_variance.maxCoeff() / static_cast<double>(windows.size()));
  if (accel_std > config.max_accel_std || gyro_std > config.max_gyro_std) {
    return Error(fmt::format("static alignment: the IMU is moving ({:.0f} ms means: specific force std {:.3f} m/s^2, limit {}; rate std {:.4f} rad/s, limit {})",
                             config.motion_window_s * 1e3, accel_std, config.max_accel_std, gyro_std, config.max_gyro_std));
  }
  const Eigen::Vector3d up_body = mounting.R_body_imu * accel_mean;
  if (up_body.norm() < 1.0) return Error(fmt::format("static alignment: specific force {:.3f} m/s^2 is too small for gravity", up_body.norm()));
  StaticAlignment alignment;
  const double roll = std::atan2(up_body.y(), up_body.z());
  const double pitch = std::atan2(-up_body.x(), std::hypot(up_body.y(), up_body.z()));
  alignment.R_world_body = rotation_from_roll_pitch_yaw(roll, pitch, yaw);
  alignment.gyro_bias = gyro_mean;
  alignment.gravity_magnitude = up_body.norm();
  alignment.samples = static_cast<int>(samples.size());
  return alignment;
}

}  // namespace hanzo::fusion::estimate
