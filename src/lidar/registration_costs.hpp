#pragma once
// Per-correspondence linearizations of the four registration methods (internal to lidar/).
// Each cost's linearize(i, pose, accumulator) finds the correspondence of source point i at
// the current pose and adds w J^T W J and w J^T W r to the normal equations, J = d r / d delta
// for T <- T Exp(delta): d(R p + t)/d(rho, phi) = [R, -R hat(p)].

#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/cloud/kdtree.hpp"
#include "hanzo/fusion/cloud/local_geometry.hpp"
#include "hanzo/fusion/core/so3.hpp"
#include "hanzo/fusion/lidar/registration.hpp"
#include "ndt_grid.hpp"

namespace hanzo::fusion::lidar {

using Matrix6d = Eigen::Matrix<double, 6, 6>;
using Vector6d = Eigen::Matrix<double, 6, 1>;
using Jacobian3x6 = Eigen::Matrix<double, 3, 6>;

/// The normal equations and statistics of one linearization (or one chunk of it).
struct NormalEquations {
  Matrix6d hessian = Matrix6d::Zero();
  Vector6d gradient = Vector6d::Zero();
  double cost = 0.0;                 // sum of w r^T W r
  double squared_distance_sum = 0.0; // sum of squared Euclidean correspondence distances, m^2
  size_t correspondences = 0;

  void add(const NormalEquations& other) {
    hessian += other.hessian;
    gradient += other.gradient;
    cost += other.cost;
    squared_distance_sum += other.squared_distance_sum;
    correspondences += other.correspondences;
  }
};

/// IRLS weight of a residual of norm `r` (Zhang 1997, "Parameter estimation techniques").
inline double kernel_weight(RobustKernel kernel, double width, double r) {
  switch (kernel) {
    case RobustKernel::kNone: return 1.0;
    case RobustKernel::kHuber: return r <= width ? 1.0 : width / r;
    case RobustKernel::kCauchy: return 1.0 / (1.0 + (r / width) * (r / width));
    case RobustKernel::kGemanMcClure: {
      const double s = 1.0 + (r / width) * (r / width);
      return 1.0 / (s * s);
    }
  }
  return 1.0;
}

/// The pose as the linearizations use it.
struct PoseBlocks {
  explicit PoseBlocks(const SE3& T) : rotation(T.rotation().matrix()), translation(T.translation()) {}
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;

  Jacobian3x6 jacobian(const Eigen::Vector3d& source_point) const {
    Jacobian3x6 J;
    J.leftCols<3>() = rotation;
    J.rightCols<3>() = -rotation * SO3::hat(source_point);
    return J;
  }
};

/// Nearest target point to q within the correspondence distance. `previous` holds each source
/// point's last correspondence (kNoCorrespondence when none), from which the search starts:
/// - with the target's neighbour lists (`neighbours`, may be null), the nearest of the previous
///   point's neighbours is the answer when it lies closer than radii[previous] - |q - previous|:
///   every target point outside the list is at least that far from q (triangle inequality), so
///   once the motion between iterations is small most correspondences need no tree search;
/// - otherwise the previous point's distance bounds the kd-tree search from the start, so the
///   descent prunes almost every branch.
/// Either way the result is the same exact nearest neighbour (up to ties).
constexpr uint32_t kNoCorrespondence = std::numeric_limits<uint32_t>::max();
inline bool find_correspondence(const cloud::KdTree& tree, const cloud::NeighbourLists* neighbours, const Eigen::Vector3d& q,
                                float max_squared_distance, uint32_t& previous, uint32_t* index, float* squared_distance) {
  const Eigen::Vector3f query = q.cast<float>();
  const std::vector<Eigen::Vector3f>& points = tree.points();
  float bound = max_squared_distance;
  if (previous != kNoCorrespondence) {
    const float to_previous = (points[previous] - query).squaredNorm();
    if (neighbours != nullptr && neighbours->k > 0) {
      const float guaranteed = neighbours->radii[previous] - std::sqrt(to_previous);
      const uint32_t* list = neighbours->indices.data() + size_t{previous} * neighbours->k;
      float best = std::numeric_limits<float>::max();
      uint32_t best_index = previous;
      for (size_t n = 0; n < neighbours->k; ++n) {
        const float distance = (points[list[n]] - query).squaredNorm();
        if (distance < best) {
          best = distance;
          best_index = list[n];
        }
      }
      if (guaranteed > 0.0f && best <= guaranteed * guaranteed) {
        const bool found = best <= max_squared_distance;
        previous = found ? best_index : kNoCorrespondence;
        *index = best_index;
        *squared_distance = best;
        return found;
      }
    }
    // Slightly above the previous point's distance, so the search finds it again at worst.
    bound = std::min(bound, to_previous * 1.0001f + 1e-12f);
  }
  const bool found = tree.nearest(query, bound, index, squared_distance) ||
                     (bound < max_squared_distance && tree.nearest(query, max_squared_distance, index, squared_distance));
  previous = found ? *index : kNoCorrespondence;
  return found;
}

/// The correspondence search shared by ICP, point-to-plane and GICP: finds source point i's
/// target point and counts it in the statistics of `out`.
struct NearestNeighborMatcher {
  const cloud::KdTree& tree;
  const cloud::NeighbourLists* neighbours;  // the target's, or null
  float max_squared_distance;
  std::vector<uint32_t>& previous;  // one per source point, see find_correspondence

  bool match(size_t i, const Eigen::Vector3d& q, uint32_t* j, NormalEquations& out) const {
    float squared_distance = 0.0f;
    if (!find_correspondence(tree, neighbours, q, max_squared_distance, previous[i], j, &squared_distance)) return false;
    out.squared_distance_sum += squared_distance;
    ++out.correspondences;
    return true;
  }
  Eigen::Vector3d target(uint32_t j) const { return tree.points()[j].cast<double>(); }
};

struct KernelSettings {
  RobustKernel kernel;
  double width;
};

/// Adds the weighted row of a point-to-plane residual r = n . (R p + t - m): w j j^T and w j r
/// with j^T = n^T [R, -R hat(p)] = [a^T, (p x a)^T], a = R^T n (`normal_rotated`); the
/// translation and rotation halves times the scales (a point that a pose step moves by more or
/// less than a rigid point: surface_registration.hpp's DeskewCoupling).
inline void accumulate_plane_row(const Eigen::Vector3d& source_point, const Eigen::Vector3d& normal_rotated, double residual,
                                 double w, NormalEquations& out, double translation_scale = 1.0, double rotation_scale = 1.0) {
  Vector6d row;
  row.head<3>() = translation_scale * normal_rotated;
  row.tail<3>() = rotation_scale * source_point.cross(normal_rotated);
  out.hessian.noalias() += (w * row) * row.transpose();
  out.gradient.noalias() += (w * residual) * row;
  out.cost += w * residual * residual;
}

/// Adds w J^T W J, w J^T W r and w r^T W r (w: the kernel's weight) of a 3-row residual
/// r = R p + t - target with J = [R, -R hat(p)], computed in the rotated frame:
/// J^T W J = K^T W' K and J^T W r = K^T W' r' with K = [I, -hat(p)], W' = R^T W R, r' = R^T r,
/// so the blocks are W', -W' hat(p), hat(p) W' and -hat(p) W' hat(p), and the gradient is
/// [W' r'; p x W' r'] (about half the multiplications of forming J and J^T W J).
/// `weight_rotated` is W', `residual_rotated` r'.
inline void accumulate_rigid(const Eigen::Vector3d& source_point, const Eigen::Matrix3d& weight_rotated,
                             const Eigen::Vector3d& residual_rotated, const KernelSettings& kernel, NormalEquations& out) {
  const Eigen::Vector3d weighted_residual = weight_rotated * residual_rotated;
  const double squared = residual_rotated.dot(weighted_residual);
  const double w = kernel_weight(kernel.kernel, kernel.width, std::sqrt(squared));
  const Eigen::Matrix3d source_hat = SO3::hat(source_point);
  const Eigen::Matrix3d weight_hat = w * (weight_rotated * source_hat);
  out.hessian.topLeftCorner<3, 3>() += w * weight_rotated;
  out.hessian.topRightCorner<3, 3>() -= weight_hat;
  out.hessian.bottomLeftCorner<3, 3>() -= weight_hat.transpose();
  out.hessian.bottomRightCorner<3, 3>().noalias() -= source_hat * weight_hat;
  out.gradient.head<3>() += w * weighted_residual;
  out.gradient.tail<3>() += w * source_point.cross(weighted_residual);
  out.cost += w * squared;
}

struct PointToPointCost {
  const std::vector<Eigen::Vector3d>& source;
  NearestNeighborMatcher matcher;
  KernelSettings kernel;

  void linearize(size_t i, const PoseBlocks& pose, NormalEquations& out) const {
    const Eigen::Vector3d q = pose.rotation * source[i] + pose.translation;
    uint32_t j = 0;
    if (!matcher.match(i, q, &j, out)) return;
    accumulate_rigid(source[i], Eigen::Matrix3d::Identity(), pose.rotation.transpose() * (q - matcher.target(j)), kernel, out);
  }
};

struct PointToPlaneCost {
  const std::vector<Eigen::Vector3d>& source;
  NearestNeighborMatcher matcher;
  const std::vector<Eigen::Vector3f>& target_normals;
  KernelSettings kernel;

  void linearize(size_t i, const PoseBlocks& pose, NormalEquations& out) const {
    const Eigen::Vector3d q = pose.rotation * source[i] + pose.translation;
    uint32_t j = 0;
    if (!matcher.match(i, q, &j, out)) return;
    const Eigen::Vector3d normal = target_normals[j].cast<double>();
    const double r = normal.dot(q - matcher.target(j));
    accumulate_plane_row(source[i], pose.rotation.transpose() * normal, r, kernel_weight(kernel.kernel, kernel.width, std::abs(r)), out);
  }
};

struct GicpCost {
  const std::vector<Eigen::Vector3d>& source;
  const std::vector<Eigen::Matrix3d>& source_covariances;
  NearestNeighborMatcher matcher;
  const std::vector<Eigen::Matrix3d>& target_covariances;
  KernelSettings kernel;

  void linearize(size_t i, const PoseBlocks& pose, NormalEquations& out) const {
    const Eigen::Vector3d q = pose.rotation * source[i] + pose.translation;
    uint32_t j = 0;
    if (!matcher.match(i, q, &j, out)) return;
    // Segal et al. 2009, eq. (2): d^T (C_t + R C_s R^T)^-1 d with d = t - (R p + t_pose), in the
    // rotated frame of accumulate_rigid: R^T (C_t + R C_s R^T)^-1 R = (R^T C_t R + C_s)^-1.
    const Eigen::Matrix3d& R = pose.rotation;
    const Eigen::Matrix3d combined_rotated = R.transpose() * target_covariances[j] * R + source_covariances[i];
    accumulate_rigid(source[i], combined_rotated.inverse(), R.transpose() * (q - matcher.target(j)), kernel, out);
  }
};

struct NdtCost {
  const std::vector<Eigen::Vector3d>& source;
  const NdtGrid& grid;
  NdtScoreConstants constants;
  KernelSettings kernel;

  void linearize(size_t i, const PoseBlocks& pose, NormalEquations& out) const {
    const Eigen::Vector3d q = pose.rotation * source[i] + pose.translation;
    const Jacobian3x6 J = pose.jacobian(source[i]);
    double nearest_squared = std::numeric_limits<double>::infinity();
    grid.for_each_neighbor(q, [&](const NdtCell& cell) {
      const Eigen::Vector3d x = q - cell.mean;
      const double mahalanobis = x.dot(cell.inverse_covariance * x);
      // Magnusson eq. 6.9: score -d1 exp(-d2/2 m); its gradient is w S^-1 x J with
      // w = -d1 d2 exp(-d2/2 m) > 0, the gradient of (w/2) x^T S^-1 x at fixed w.
      const double w = -constants.d1 * constants.d2 * std::exp(-0.5 * constants.d2 * mahalanobis) *
                       kernel_weight(kernel.kernel, kernel.width, std::sqrt(mahalanobis));
      const Eigen::Matrix<double, 6, 3> JtW = J.transpose() * cell.inverse_covariance;
      out.hessian.noalias() += w * JtW * J;
      out.gradient.noalias() += w * JtW * x;
      out.cost += w * mahalanobis;
      nearest_squared = std::min(nearest_squared, x.squaredNorm());
    });
    if (std::isfinite(nearest_squared)) {
      out.squared_distance_sum += nearest_squared;
      ++out.correspondences;
    }
  }
};

}  // namespace hanzo::fusion::lidar
