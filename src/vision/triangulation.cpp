#include "triangulation.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/SVD>

namespace hanzo::fusion::vision {

std::optional<Eigen::Vector3d> triangulate(const SE3& T_camera1_world, const Eigen::Vector2d& normalized1, const SE3& T_camera2_world,
                                           const Eigen::Vector2d& normalized2) {
  const Eigen::Matrix<double, 3, 4> P1 = T_camera1_world.matrix().topRows<3>();
  const Eigen::Matrix<double, 3, 4> P2 = T_camera2_world.matrix().topRows<3>();
  Eigen::Matrix4d system;
  system.row(0) = normalized1.x() * P1.row(2) - P1.row(0);
  system.row(1) = normalized1.y() * P1.row(2) - P1.row(1);
  system.row(2) = normalized2.x() * P2.row(2) - P2.row(0);
  system.row(3) = normalized2.y() * P2.row(2) - P2.row(1);
  const Eigen::Vector4d homogeneous = Eigen::JacobiSVD<Eigen::Matrix4d>(system, Eigen::ComputeFullV).matrixV().col(3);
  if (std::abs(homogeneous(3)) < 1e-12) return std::nullopt;
  const Eigen::Vector3d point = homogeneous.head<3>() / homogeneous(3);
  if (!point.allFinite()) return std::nullopt;
  return point;
}

std::optional<Eigen::Vector3d> triangulate_views(const std::vector<SE3>& T_camera_world, const std::vector<Eigen::Vector2d>& normalized) {
  if (T_camera_world.size() < 2 || T_camera_world.size() != normalized.size()) return std::nullopt;
  Eigen::MatrixXd system(2 * T_camera_world.size(), 4);
  for (std::size_t i = 0; i < T_camera_world.size(); ++i) {
    const Eigen::Matrix<double, 3, 4> P = T_camera_world[i].matrix().topRows<3>();
    system.row(static_cast<Eigen::Index>(2 * i)) = normalized[i].x() * P.row(2) - P.row(0);
    system.row(static_cast<Eigen::Index>(2 * i + 1)) = normalized[i].y() * P.row(2) - P.row(1);
  }
  const Eigen::Vector4d homogeneous = Eigen::JacobiSVD<Eigen::MatrixXd>(system, Eigen::ComputeFullV).matrixV().col(3);
  if (std::abs(homogeneous(3)) < 1e-12) return std::nullopt;
  const Eigen::Vector3d point = homogeneous.head<3>() / homogeneous(3);
  if (!point.allFinite()) return std::nullopt;
  return point;
}

double triangulation_angle(const SE3& T_camera1_world, const SE3& T_camera2_world, const Eigen::Vector3d& point_world) {
  const Eigen::Vector3d centre1 = T_camera1_world.inverse().translation(), centre2 = T_camera2_world.inverse().translation();
  const Eigen::Vector3d ray1 = point_world - centre1, ray2 = point_world - centre2;
  const double cosine = ray1.dot(ray2) / (ray1.norm() * ray2.norm());
  return std::acos(std::clamp(cosine, -1.0, 1.0));
}

}  // namespace hanzo::fusion::vision
