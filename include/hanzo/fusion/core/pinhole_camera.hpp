#pragma once
// PinholeCamera: projection of camera-frame points to pixels through a pinhole model with lens
// distortion, with its Jacobian, for measurement models (landmark projection factors, visual
// frontends). Conventions as OpenCV and the spec's calibration:
//   camera frame: x right, y down, z forward (optical axis); pixels: u right, v down, origin at
//   the centre of the top-left pixel.
//   normalized:  x_n = X / Z, y_n = Y / Z
//   radtan (OpenCV plumb_bob, coefficients k1 k2 p1 p2 k3), r2 = x_n^2 + y_n^2:
//     radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
//     x_d = x_n radial + 2 p1 x_n y_n + p2 (r2 + 2 x_n^2),  y_d = y_n radial + p1 (r2 + 2 y_n^2) + 2 p2 x_n y_n
//   equidistant (OpenCV fisheye, k1..k4): theta = atan(r), r = |(x_n, y_n)|,
//     theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8), (x_d, y_d) = theta_d / r (x_n, y_n)
//   pixel: u = fx x_d + cx, v = fy y_d + cy.
// Points at or behind min_depth (metres along z) do not project.

#include <array>
#include <optional>

#include <Eigen/Core>

namespace hanzo::fusion {

struct PinholeCamera {
  enum class Distortion { kNone, kRadtan, kEquidistant };

  double fx = 1.0, fy = 1.0, cx = 0.0, cy = 0.0;  ///< pixels
  Distortion distortion = Distortion::kNone;
  std::array<double, 5> coefficients{};           ///< radtan: k1 k2 p1 p2 k3; equidistant: k1 k2 k3 k4
  double min_depth = 1e-6;                        ///< metres

  /// The pixel of a camera-frame point, or nullopt when its depth is below min_depth.
  /// jacobian (optional): d pixel / d point, 2x3.
  std::optional<Eigen::Vector2d> project(const Eigen::Vector3d& point_camera, Eigen::Matrix<double, 2, 3>* jacobian = nullptr) const;

  /// The distorted normalized coordinates of normalized ones; jacobian: d distorted / d normalized.
  Eigen::Vector2d distort(const Eigen::Vector2d& normalized, Eigen::Matrix2d* jacobian = nullptr) const;

  /// The inverse of distort() by Gauss-Newton from the distorted point (at most 20 steps, to
  /// 1e-10); nullopt where it does not converge (outside the region where the model is
  /// invertible, far beyond the calibrated field of view).
  std::optional<Eigen::Vector2d> undistort(const Eigen::Vector2d& distorted) const;

  /// The normalized coordinates (x/z, y/z) of a pixel: undistort() of its distorted coordinates.
  std::optional<Eigen::Vector2d> unproject(const Eigen::Vector2d& pixel) const;
};

}  // namespace hanzo::fusion
