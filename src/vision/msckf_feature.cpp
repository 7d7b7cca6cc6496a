#include "msckf_feature.hpp"

#include <Eigen/Eigenvalues>
#include <Eigen/LU>

#include <algorithm>
#include <cmath>

namespace hanzo::fusion::vision {

FeatureLinearization linearize_observation(const FeatureView& view, const Eigen::Vector3d& point_world) {
  const Eigen::Matrix3d R_world_body = view.T_world_body.rotation().matrix();
  const Eigen::Matrix3d R_camera_body = view.T_body_camera.rotation().matrix().transpose();
  const Eigen::Vector3d point_body = R_world_body.transpose() * (point_world - view.T_world_body.translation());
  const Eigen::Vector3d point_camera = R_camera_body * (point_body - view.T_body_camera.translation());
  FeatureLinearization out;
  out.depth = point_camera.z();
  const double inverse_depth = 1.0 / point_camera.z();
  const Eigen::Vector2d predicted = point_camera.head<2>() * inverse_depth;
  out.residual = view.normalized - predicted;
  Eigen::Matrix<double, 2, 3> projection;
  projection << inverse_depth, 0.0, -predicted.x() * inverse_depth, 0.0, inverse_depth, -predicted.y() * inverse_depth;
  const Eigen::Matrix3d camera_by_world = R_camera_body * R_world_body.transpose();
  out.by_point = projection * camera_by_world;
  out.by_clone.leftCols<3>() = -out.by_point;
  out.by_clone.rightCols<3>() = projection * R_camera_body * SO3::hat(point_body);
  out.by_extrinsic.leftCols<3>() = -projection * R_camera_body;
  out.by_extrinsic.rightCols<3>() = projection * SO3::hat(point_camera);
  return out;
}

namespace {

bool depths_within(const std::vector<FeatureView>& views, const Eigen::Vector3d& point, const FeatureTriangulationConfig& config) {
  for (const FeatureView& view : views) {
    const double depth = (view.T_world_body * view.T_body_camera).inverse().act(point).z();
    if (!(depth >= config.min_depth && depth <= config.max_depth)) return false;
  }
  return true;
}

}  // namespace

std::optional<Eigen::Vector3d> triangulate_feature(const std::vector<FeatureView>& views, const FeatureTriangulationConfig& config) {
  if (views.size() < 2) return std::nullopt;
  // Linear: each view contributes the two rows of [b]x (R p + t) = 0 that do not vanish at z.
  Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
  Eigen::Vector3d right_side = Eigen::Vector3d::Zero();
  for (const FeatureView& view : views) {
    const SE3 T_camera_world = (view.T_world_body * view.T_body_camera).inverse();
    const Eigen::Matrix3d R = T_camera_world.rotation().matrix();
    const Eigen::Vector3d& t = T_camera_world.translation();
    Eigen::Matrix<double, 2, 3> rows;
    rows.row(0) = view.normalized.x() * R.row(2) - R.row(0);
    rows.row(1) = view.normalized.y() * R.row(2) - R.row(1);
    const Eigen::Vector2d constant(t.x() - view.normalized.x() * t.z(), t.y() - view.normalized.y() * t.z());
    normal += rows.transpose() * rows;
    right_side += rows.transpose() * constant;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(normal);
  const Eigen::Vector3d eigenvalues = eigen.eigenvalues();
  if (!(eigenvalues(0) > 1e-9 * eigenvalues(2))) return std::nullopt;
  Eigen::Vector3d point = normal.ldlt().solve(right_side);
  if (!point.allFinite() || !depths_within(views, point, config)) return std::nullopt;

  // Gauss-Newton on the reprojection errors (normalized units).
  for (int iteration = 0; iteration < config.iterations; ++iteration) {
    Eigen::Matrix3d hessian = Eigen::Matrix3d::Zero();
    Eigen::Vector3d gradient = Eigen::Vector3d::Zero();
    for (const FeatureView& view : views) {
      const FeatureLinearization linear = linearize_observation(view, point);
      if (linear.depth <= 0.0) return std::nullopt;
      hessian += linear.by_point.transpose() * linear.by_point;
      gradient += linear.by_point.transpose() * linear.residual;
    }
    const Eigen::Vector3d step = hessian.ldlt().solve(gradient);
    if (!step.allFinite()) return std::nullopt;
    point += step;
    if (step.norm() < 1e-9 * (1.0 + point.norm())) break;
  }
  if (!point.allFinite() || !depths_within(views, point, config)) return std::nullopt;
  // The widest angle between two of the viewing rays.
  double widest = 0.0;
  for (size_t i = 0; i < views.size(); ++i) {
    const Eigen::Vector3d ray_i = (point - (views[i].T_world_body * views[i].T_body_camera).translation()).normalized();
    for (size_t j = i + 1; j < views.size(); ++j) {
      const Eigen::Vector3d ray_j = (point - (views[j].T_world_body * views[j].T_body_camera).translation()).normalized();
      widest = std::max(widest, std::atan2(ray_i.cross(ray_j).norm(), ray_i.dot(ray_j)));
    }
  }
  if (widest < config.min_parallax_rad) return std::nullopt;
  return point;
}

}  // namespace hanzo::fusion::vision
