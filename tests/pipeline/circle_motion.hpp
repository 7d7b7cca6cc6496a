#pragma once
// A body circling at 1.5 m/s (radius 3 m, 0.5 rad/s, heaving 0.3 m), facing along its motion,
// and the exact IMU readings of its origin (body axes): the keyframe factor tests' motion.

#include <cmath>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"

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

}  // namespace hanzo::fusion::pipeline::circle_motion
