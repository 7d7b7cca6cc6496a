#pragma once
// Landmark observations by cameras: a pixel of a world point L(j) seen from the pose X(i), mono
// (any PinholeCamera distortion) or from a rectified stereo pair.
//
// Frames: X(i) = T_world_body (SE3, right perturbation), L(j) world point (Vector3), the camera
// mounted at T_body_camera (the calibration's camera_to_body).
//   p_body = T_world_body^-1 p_world,  p_camera = T_body_camera^-1 p_body
// Jacobians: d p_body / d rho = -I, d p_body / d phi = [p_body]x, d p_body / d p_world = R_world_body^T,
// d p_camera / d p_body = R_body_camera^T, then the camera's d pixel / d p_camera.
//
// A landmark at or behind the camera (depth <= the camera's min_depth) fails to evaluate: the
// optimizer rejects a step that puts it there (GTSAM's cheirality exception).

#include <optional>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/graph/factor.hpp"

namespace hanzo::fusion::graph {

/// r = project(p_camera) - measured pixel, noise 2x2 (pixels).
class ProjectionFactor final : public Factor {
 public:
  ProjectionFactor(Key pose, Key landmark, const Eigen::Vector2d& measured, const PinholeCamera& camera, const SE3& T_body_camera,
                   GaussianNoise noise)
      : Factor({pose, landmark}), measured_(measured), camera_(camera), T_body_camera_(T_body_camera), noise_(std::move(noise)) {}
  int dimension() const override { return noise_.dimension(); }
  /// Fails when the landmark is at or behind the camera or the noise is not 2x2.
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

  using Residual = Eigen::Vector2d;
  using PoseJacobian = Eigen::Matrix<double, 2, 6>;
  using PointJacobian = Eigen::Matrix<double, 2, 3>;
  /// The whitened residual at (T_world_body, p_world) and, when asked, its Jacobians:
  /// evaluate()'s work without the Values lookup and in fixed-size types (the batch optimizer's
  /// fast path). nullopt when the landmark is at or behind the camera. Requires dimension() == 2.
  std::optional<Residual> whitened_error(const SE3& T_world_body, const Eigen::Vector3d& p_world, PoseJacobian* d_pose,
                                         PointJacobian* d_point) const;

 private:
  Eigen::Vector2d measured_;
  PinholeCamera camera_;
  SE3 T_body_camera_;
  GaussianNoise noise_;
};

/// A rectified stereo pair (GTSAM's StereoCamera): the left camera at T_body_camera with the
/// intrinsics of `camera` (its distortion must be none: rectified images), the right one
/// `baseline` metres along the left camera's x axis. Measurement (u_left, u_right, v):
///   u_left = fx X / Z + cx,  u_right = fx (X - baseline) / Z + cx,  v = fy Y / Z + cy.
/// r = predicted - measured, noise 3x3 (pixels).
class StereoProjectionFactor final : public Factor {
 public:
  StereoProjectionFactor(Key pose, Key landmark, const Eigen::Vector3d& measured, const PinholeCamera& camera, double baseline,
                         const SE3& T_body_camera, GaussianNoise noise)
      : Factor({pose, landmark}), measured_(measured), camera_(camera), baseline_(baseline), T_body_camera_(T_body_camera),
        noise_(std::move(noise)) {}
  int dimension() const override { return noise_.dimension(); }
  /// Fails when the landmark is at or behind the camera, the camera has distortion or the
  /// noise is not 3x3.
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

  using Residual = Eigen::Vector3d;
  using PoseJacobian = Eigen::Matrix<double, 3, 6>;
  using PointJacobian = Eigen::Matrix3d;
  /// As ProjectionFactor::whitened_error; nullopt also when the camera has distortion.
  /// Requires dimension() == 3.
  std::optional<Residual> whitened_error(const SE3& T_world_body, const Eigen::Vector3d& p_world, PoseJacobian* d_pose,
                                         PointJacobian* d_point) const;

 private:
  Eigen::Vector3d measured_;
  PinholeCamera camera_;
  double baseline_;
  SE3 T_body_camera_;
  GaussianNoise noise_;
};

}  // namespace hanzo::fusion::graph
