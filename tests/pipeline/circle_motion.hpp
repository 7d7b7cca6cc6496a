#pragma once
// A body circling at 1.5 m/s (radius 3 m, 0.5 rad/s, heaving 0.3 m), facing along its motion,
// and the exact IMU readings of its origin (body axes): the keyframe factor tests' motion.

#include <cmath>
#include <random>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"

namespace hanzo::fusion::pipeline::circle_motion {

constexpr double kRadius = 3.0;
constexpr double kRate = 0.5;
constexpr double kStart = 100.0;  // s: t = 0 of the motion
inline const Eigen::Vector3d kGravity(0.0, 0.0, -9.80665);

inline SE3 true_pose(double t) {
  const Eigen::Vector3d position(kRadius * std::cos(kRate * t), kRadius * std::sin(kRate * t), 0.3 * std::sin(2.0 * kRate * t));
  return SE3(SO3::exp(Eigen::Vector3d(0.0, 0.0, kRate * t + M_PI / 2.0)), position);
}

inline Eigen::Vector3d true_velocity(double t) {
  return Eigen::Vector3d(-kRadius * kRate * std::sin(kRate * t), kRadius * kRate * std::cos(kRate * t), 0.6 * kRate * std::cos(2.0 * kRate * t));
}

// The IMU reading of the sample at t, held over (t - dt, t]: the motion at the interval's middle.
inline estimate::ImuSample imu_sample(double t, double dt) {
  const double m = t - dt / 2.0;
  const Eigen::Vector3d acceleration(-kRadius * kRate * kRate * std::cos(kRate * m), -kRadius * kRate * kRate * std::sin(kRate * m),
                                     -1.2 * kRate * kRate * std::sin(2.0 * kRate * m));
  const SO3 R_world_body = true_pose(m).rotation();
  return {Timestamp::from_seconds(kStart + t), Eigen::Vector3d(0.0, 0.0, kRate), R_world_body.inverse() * (acceleration - kGravity)};
}

// The Frontend's keyframe `id` at t: the pose 10 cm / 1 degree off the truth (exact for the first,
// which carries a tight pose covariance), the relative motion from `previous` (covariance 1e-2),
// the velocity off by velocity_noise per axis.
inline msgs::Keyframe noisy_keyframe(uint64_t id, double t, const msgs::Keyframe* previous, double velocity_noise, std::mt19937_64& random) {
  std::normal_distribution<double> normal(0.0, 1.0);
  msgs::Keyframe keyframe;
  keyframe.keyframe_id = id;
  keyframe.timestamp = Timestamp::from_seconds(kStart + t);
  const SE3 T_world_body = true_pose(t);
  SE3 believed = T_world_body;
  if (previous != nullptr) {
    const Eigen::Vector3d position_error = 0.1 * Eigen::Vector3d(normal(random), normal(random), normal(random)).normalized();
    const Eigen::Vector3d rotation_error = (M_PI / 180.0) * Eigen::Vector3d(normal(random), normal(random), normal(random)).normalized();
    believed = SE3(T_world_body.rotation() * SO3::exp(rotation_error), T_world_body.translation() + position_error);
    keyframe.previous_keyframe_id = previous->keyframe_id;
    keyframe.T_previous_current = msgs::Pose::from_se3(previous->T_world_body.to_se3().inverse() * believed);
    keyframe.relative_covariance = Eigen::Matrix<double, 6, 6>::Identity() * 1e-2;
  } else {
    keyframe.pose_covariance = Eigen::Matrix<double, 6, 6>::Identity() * 1e-8;
  }
  keyframe.T_world_body = msgs::Pose::from_se3(believed);
  keyframe.velocity = true_velocity(t) + velocity_noise * Eigen::Vector3d(normal(random), normal(random), normal(random));
  return keyframe;
}

}  // namespace hanzo::fusion::pipeline::circle_motion
