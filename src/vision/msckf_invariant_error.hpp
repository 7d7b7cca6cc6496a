#pragma once
// The MSCKF's error coordinates (msckf.hpp): the right-invariant error of the IMU's extended pose
// and of each clone, and its conversion to NavigationState's body-frame error.
//
//   invariant:  R = Exp(phi) R_est,        v = Exp(phi) v_est + xi_v,  p = Exp(phi) p_est + xi_p
//   body frame: R = R_est Exp(dtheta),     v = v_est + dv,             p = p_est + dp
// To first order dtheta = R_est^T phi, dv = xi_v - [v_est]x phi, dp = xi_p - [p_est]x phi.
// Error orders: pose (p, rotation); IMU (p, rotation, v, accel bias, gyro bias), biases additive.
// (tests/vision/msckf_test.cpp checks them against the exact maps.)

#include <Eigen/Core>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/estimate/navigation_state.hpp"

namespace hanzo::fusion::vision {

using PoseErrorMatrix = Eigen::Matrix<double, 6, 6>;
using ImuErrorMatrix = Eigen::Matrix<double, 15, 15>;

/// (dp, dtheta) = T (xi_p, phi) for a pose.
inline PoseErrorMatrix pose_error_from_invariant(const SO3& R_world_body, const Eigen::Vector3d& position) {
  PoseErrorMatrix T = PoseErrorMatrix::Identity();
  T.topRightCorner<3, 3>() = -SO3::hat(position);
  T.bottomRightCorner<3, 3>() = R_world_body.matrix().transpose();
  return T;
}

/// (dp, dtheta, dv, dba, dbg) = T (xi_p, phi, xi_v, dba, dbg) for the IMU state.
inline ImuErrorMatrix imu_error_from_invariant(const estimate::NavigationState& state) {
  ImuErrorMatrix T = ImuErrorMatrix::Identity();
  T.block<3, 3>(0, 3) = -SO3::hat(state.position);
  T.block<3, 3>(3, 3) = state.R_world_body.matrix().transpose();
  T.block<3, 3>(6, 3) = -SO3::hat(state.velocity);
  return T;
}

/// The inverse: phi = R dtheta, xi_p = dp + [p]x R dtheta, xi_v = dv + [v]x R dtheta.
inline ImuErrorMatrix invariant_from_imu_error(const estimate::NavigationState& state) {
  const Eigen::Matrix3d R = state.R_world_body.matrix();
  ImuErrorMatrix T = ImuErrorMatrix::Identity();
  T.block<3, 3>(0, 3) = SO3::hat(state.position) * R;
  T.block<3, 3>(3, 3) = R;
  T.block<3, 3>(6, 3) = SO3::hat(state.velocity) * R;
  return T;
}

/// The state with an invariant error applied (the exact map above; biases added).
inline estimate::NavigationState apply_invariant_error(const estimate::NavigationState& state, const Eigen::Matrix<double, 15, 1>& error) {
  const SO3 rotation = SO3::exp(error.segment<3>(3));
  estimate::NavigationState out = state;
  out.R_world_body = rotation * state.R_world_body;
  out.velocity = rotation * state.velocity + error.segment<3>(6);
  out.position = rotation * state.position + error.segment<3>(0);
  out.accel_bias += error.segment<3>(9);
  out.gyro_bias += error.segment<3>(12);
  return out;
}

/// A pose with an invariant error (xi_p, phi) applied.
inline SE3 apply_invariant_error(const SE3& T_world_body, const Eigen::Matrix<double, 6, 1>& error) {
  const SO3 rotation = SO3::exp(error.tail<3>());
  return SE3(rotation * T_world_body.rotation(), rotation * T_world_body.translation() + error.head<3>());
}

}  // namespace hanzo::fusion::vision
