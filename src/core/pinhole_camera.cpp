#include "hanzo/fusion/core/pinhole_camera.hpp"

#include <cmath>

#include <Eigen/LU>

namespace hanzo::fusion {

Eigen::Vector2d PinholeCamera::distort(const Eigen::Vector2d& normalized, Eigen::Matrix2d* jacobian) const {
  const double x = normalized.x(), y = normalized.y(), r2 = x * x + y * y;
  const std::array<double, 5>& k = coefficients;
  switch (distortion) {
    case Distortion::kNone:
      if (jacobian != nullptr) jacobian->setIdentity();
      return normalized;
    case Distortion::kRadtan: {
      const double p1 = k[2], p2 = k[3];
      const double radial = 1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]));
      const double radial_dr2 = k[0] + r2 * (2.0 * k[1] + 3.0 * r2 * k[4]);
      if (jacobian != nullptr) {
        *jacobian << radial + 2.0 * x * x * radial_dr2 + 2.0 * p1 * y + 6.0 * p2 * x, 2.0 * x * y * radial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y,
            2.0 * x * y * radial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y, radial + 2.0 * y * y * radial_dr2 + 6.0 * p1 * y + 2.0 * p2 * x;
      }
      return {x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x), y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y};
    }
    case Distortion::kEquidistant: {
      const double r = std::sqrt(r2);
      if (r < 1e-12) {
        if (jacobian != nullptr) jacobian->setIdentity();
        return normalized;
      }
      const double theta = std::atan(r), t2 = theta * theta;
      const double theta_d = theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))));
      const double scale = theta_d / r;
      if (jacobian != nullptr) {
        const double dtheta_d_dtheta = 1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])));
        const double dscale_dr = (dtheta_d_dtheta / (1.0 + r2) * r - theta_d) / r2;
        *jacobian = scale * Eigen::Matrix2d::Identity() + (dscale_dr / r) * normalized * normalized.transpose();
      }
      return scale * normalized;
    }
  }
  return normalized;
}

std::optional<Eigen::Vector2d> PinholeCamera::undistort(const Eigen::Vector2d& distorted) const {
  if (distortion == Distortion::kNone) return distorted;
  Eigen::Vector2d normalized = distorted;
  for (int step = 0; step < 20; ++step) {
    Eigen::Matrix2d jacobian;
    const Eigen::Vector2d residual = distort(normalized, &jacobian) - distorted;
    if (residual.norm() < 1e-10) return normalized;
    const Eigen::Vector2d correction = jacobian.partialPivLu().solve(residual);
    if (!correction.allFinite()) return std::nullopt;
    normalized -= correction;
  }
  return (distort(normalized) - distorted).norm() < 1e-8 ? std::optional<Eigen::Vector2d>(normalized) : std::nullopt;
}

std::optional<Eigen::Vector2d> PinholeCamera::unproject(const Eigen::Vector2d& pixel) const {
  return undistort({(pixel.x() - cx) / fx, (pixel.y() - cy) / fy});
}

std::optional<Eigen::Vector2d> PinholeCamera::project(const Eigen::Vector3d& point_camera, Eigen::Matrix<double, 2, 3>* jacobian) const {
  const double z = point_camera.z();
  if (!(z > min_depth)) return std::nullopt;
  const Eigen::Vector2d normalized = point_camera.head<2>() / z;
  Eigen::Matrix2d distortion_jacobian;
  const Eigen::Vector2d distorted = distort(normalized, jacobian != nullptr ? &distortion_jacobian : nullptr);
  if (jacobian != nullptr) {
    Eigen::Matrix<double, 2, 3> normalized_jacobian;
    normalized_jacobian << 1.0 / z, 0.0, -normalized.x() / z, 0.0, 1.0 / z, -normalized.y() / z;
    *jacobian = Eigen::DiagonalMatrix<double, 2>(fx, fy) * distortion_jacobian * normalized_jacobian;
  }
  return Eigen::Vector2d(fx * distorted.x() + cx, fy * distorted.y() + cy);
}

}  // namespace hanzo::fusion
