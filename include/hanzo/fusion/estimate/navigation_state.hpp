#pragma once
// NavigationState: the state the frontend filters estimate (spec, "State Representation"):
//
//   position        p  [m]      body origin in the world frame (ENU)
//   orientation     R  (unit quaternion w, x, y, z)  R_world_body, body FLU
//   velocity        v  [m/s]    body origin, world frame
//   accel_bias      ba [m/s^2]  accelerometer bias, IMU axes
//   gyro_bias       bg [rad/s]  gyroscope bias, IMU axes
//   gravity         g  [m/s^2]  gravity vector in the world frame, about (0, 0, -9.81)
//   wheel_speed_scale  s  [1]   wheel odometry's distance per true distance (1 + the wheel
//                               radius error): a 2 % too large radius reads s = 1.02
//   gyro_yaw_scale     c  [1]   the gyroscope's reading of a turn about the body's z axis per
//                               true turn rate: a gyro whose yaw axis reads 1 % high has c = 1.01
//   wheel_heading_drift d [rad/m] the turn the wheels report per metre driven straight: unequal
//                               wheel scales s_r != s_l on an axle of b metres give d = (s_r - s_l) / b
//
// The spec's list sums to 3 + 4 + 3 + 3 + 3 + 3 = 19 numbers (18 degrees of freedom with the
// unit-norm quaternion); the wheel speed scale is added because an uncalibrated wheel radius
// otherwise biases every fused wheel speed (a 2 % error is 0.25 m/s at 45 km/h, five times the
// wheels' noise); the gyro's yaw-rate scale and the wheels' heading drift because with the
// wheels' yaw rate fused, a 1 % gyro scale error (3.6 deg of heading per full turn) and a 0.3 %
// difference of the wheel radii (0.02 rad/s at 12.5 m/s on a 1.6 m axle) are otherwise blamed on
// the heading. Where they are not observable they are constant and have zero variance. The error
// state has kErrorStateDimension = 21 entries. (Recorded in docs/frontend.md.)
//
// Error state (on the manifold), order fixed by ErrorIndex:
//   x_true = x (+) dx:  p + dp,  R Exp(dtheta)  (right perturbation, dtheta in the BODY frame,
//   as PoseEstimate's covariance), v + dv, ba + dba, bg + dbg, g + dg, s + ds, c + dc, d + dd.

#include <Eigen/Core>

#include "hanzo/fusion/core/so3.hpp"
#include "hanzo/fusion/core/time.hpp"

namespace hanzo::fusion::estimate {

inline constexpr int kErrorStateDimension = 21;

/// Offsets of each block (3 entries; the scales and the heading drift 1) in the error state and its covariance.
enum ErrorIndex : int {
  kPositionIndex = 0,
  kOrientationIndex = 3,
  kVelocityIndex = 6,
  kAccelBiasIndex = 9,
  kGyroBiasIndex = 12,
  kGravityIndex = 15,
  kWheelScaleIndex = 18,
  kGyroYawScaleIndex = 19,
  kWheelHeadingDriftIndex = 20,
};

using ErrorVector = Eigen::Matrix<double, kErrorStateDimension, 1>;
using ErrorCovariance = Eigen::Matrix<double, kErrorStateDimension, kErrorStateDimension>;

/// Standard gravity (m/s^2), the default magnitude of the gravity state.
inline constexpr double kStandardGravity = 9.80665;

struct NavigationState {
  Timestamp timestamp;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  SO3 R_world_body;
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d gravity{0.0, 0.0, -kStandardGravity};
  double wheel_speed_scale = 1.0;
  double gyro_yaw_scale = 1.0;
  double wheel_heading_drift = 0.0;

  /// x (+) dx as defined above.
  NavigationState plus(const ErrorVector& delta) const;
  /// The dx with other.plus(dx) == *this (rotation part log(R_other^T R_this)).
  ErrorVector minus(const NavigationState& other) const;
  /// True when every number is finite.
  bool all_finite() const;
};

/// Forces exact symmetry (averaging with the transpose); filters call it after every step.
void symmetrize(ErrorCovariance& covariance);

}  // namespace hanzo::fusion::estimate
