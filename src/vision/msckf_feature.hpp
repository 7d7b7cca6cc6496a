#pragma once
// The feature side of the MSCKF update (msckf.hpp): a point seen from several camera poses is
// triangulated, and each observation's residual is linearized in the clone pose and the point.
//
// Measurement model of one observation, camera c on clone i (T_world_body = (R, p)):
//   p_body   = R^T (p_f - p)
//   p_camera = R_body_camera^T (p_body - p_body_camera)
//   z        = (p_camera.x / p_camera.z, p_camera.y / p_camera.z)   undistorted normalized
// Jacobians (right perturbation R Exp(dtheta), p + dp, p_f + dp_f):
//   dz/dp_camera = 1/Z [1 0 -x/z; 0 1 -y/z]
//   dp_camera/dp_f = R_body_camera^T R^T,  dp_camera/dp = -R_body_camera^T R^T,
//   dp_camera/dtheta = R_body_camera^T [p_body]x
// and by the camera's extrinsics (R_body_camera Exp(dphi), p_body_camera + dq):
//   dp_camera/dq = -R_body_camera^T,  dp_camera/dphi = [p_camera]x
// (tests/vision/msckf_test.cpp checks them numerically).

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/vision/feature_triangulation.hpp"

namespace hanzo::fusion::vision {

/// The linearized observation: residual = measured - predicted, and its Jacobians by the clone's
/// (dp, dtheta), by the point's world position and by the camera's extrinsics.
struct FeatureLinearization {
  Eigen::Vector2d residual = Eigen::Vector2d::Zero();
  Eigen::Matrix<double, 2, 6> by_clone = Eigen::Matrix<double, 2, 6>::Zero();
  Eigen::Matrix<double, 2, 3> by_point = Eigen::Matrix<double, 2, 3>::Zero();
  Eigen::Matrix<double, 2, 6> by_extrinsic = Eigen::Matrix<double, 2, 6>::Zero();  ///< by (dq, dphi) of T_body_camera
  double depth = 0.0;  ///< the point's z in the camera, metres
};

FeatureLinearization linearize_observation(const FeatureView& view, const Eigen::Vector3d& point_world);

}  // namespace hanzo::fusion::vision
