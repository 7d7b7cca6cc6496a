#include "hanzo/fusion/lidar/planar_icp.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include "hanzo/fusion/cloud/kdtree.hpp"

namespace hanzo::fusion::lidar {
namespace {

Eigen::Vector3f lift(const Eigen::Vector2d& point) { return {static_cast<float>(point.x()), static_cast<float>(point.y()), 0.0F}; }

Status check_points(const PlanarPoints& points, const char* what) {
  if (points.empty()) return Error(fmt::format("planar ICP: the {} is empty", what));
  for (size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) return Error(fmt::format("planar ICP: {} point {} is not finite", what, i));
  }
  return {};
}

// Normal equations of one iteration (tangent order x, y, theta).
struct PlanarEquations {
  Eigen::Matrix3d hessian = Eigen::Matrix3d::Zero();
  Eigen::Vector3d gradient = Eigen::Vector3d::Zero();
  double weighted_squared_residuals = 0.0;
  double squared_residuals = 0.0;
  size_t correspondences = 0;
};

}  // namespace

Status PlanarIcpConfig::validate() const {
  if (!(max_correspondence_distance > 0)) return Error(fmt::format("max_correspondence_distance: {} <= 0", max_correspondence_distance));
  for (double gate : coarse_correspondence_distances) {
    if (!(gate > 0)) return Error(fmt::format("coarse_correspondence_distances: {} <= 0", gate));
  }
  if (max_iterations < 1) return Error(fmt::format("max_iterations: {} < 1", max_iterations));
  if (!(translation_tolerance > 0) || !(rotation_tolerance > 0)) return Error("translation_tolerance / rotation_tolerance must be > 0");
  if (!(huber_width > 0)) return Error(fmt::format("huber_width: {} <= 0", huber_width));
  if (normal_neighbours < 3) return Error(fmt::format("normal_neighbours: {} < 3", normal_neighbours));
  if (!(normal_radius > 0)) return Error(fmt::format("normal_radius: {} <= 0", normal_radius));
  if (!(point_cluster_radius > 0)) return Error(fmt::format("point_cluster_radius: {} <= 0", point_cluster_radius));
  if (!(point_sigma > 0)) return Error(fmt::format("point_sigma: {} <= 0", point_sigma));
  if (!(guess_translation_sigma >= 0) || !(guess_rotation_sigma >= 0)) return Error("guess_translation_sigma / guess_rotation_sigma must be >= 0");
  if (!(max_line_eigenvalue_ratio > 0 && max_line_eigenvalue_ratio < 1)) {
    return Error(fmt::format("max_line_eigenvalue_ratio: {} outside (0, 1)", max_line_eigenvalue_ratio));
  }
  return {};
}

struct PlanarTarget::Impl {
  PlanarPoints points;
  std::vector<Eigen::Vector2d> normals;
  cloud::KdTree tree{std::vector<Eigen::Vector3f>{}};
};

PlanarTarget::PlanarTarget(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
PlanarTarget::~PlanarTarget() = default;
PlanarTarget::PlanarTarget(PlanarTarget&&) noexcept = default;
PlanarTarget& PlanarTarget::operator=(PlanarTarget&&) noexcept = default;
const PlanarPoints& PlanarTarget::points() const { return impl_->points; }
const std::vector<Eigen::Vector2d>& PlanarTarget::normals() const { return impl_->normals; }

long PlanarTarget::nearest(const Eigen::Vector2d& query, double max_squared_distance, double* squared_distance) const {
  uint32_t index = 0;
  float distance = 0;
  if (!impl_->tree.nearest(lift(query), static_cast<float>(max_squared_distance), &index, &distance)) return -1;
  if (squared_distance != nullptr) *squared_distance = distance;
  return static_cast<long>(index);
}

Result<PlanarTarget> PlanarTarget::create(PlanarPoints points, const PlanarIcpConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  HANZO_RETURN_IF_ERROR(check_points(points, "target"));
  auto impl = std::make_unique<Impl>();
  std::vector<Eigen::Vector3f> lifted(points.size());
  std::transform(points.begin(), points.end(), lifted.begin(), lift);
  impl->tree = cloud::KdTree(std::move(lifted));
  impl->normals.assign(points.size(), Eigen::Vector2d::Zero());
  const auto k = static_cast<size_t>(config.normal_neighbours);
  std::vector<uint32_t> indices(k);
  std::vector<float> squared_distances(k);
  const double radius_squared = config.normal_radius * config.normal_radius;
  const double cluster_radius_squared = config.point_cluster_radius * config.point_cluster_radius;
  std::vector<bool> keep(points.size(), false);
  size_t line_like = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    const size_t found = impl->tree.knn(lift(points[i]), k, indices.data(), squared_distances.data());
    // A dense cluster (a corner, a pole, clutter) is matched point-to-point when it is no line.
    keep[i] = found >= 4 && squared_distances[3] <= cluster_radius_squared;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    size_t used = 0;
    for (size_t n = 0; n < found && squared_distances[n] <= radius_squared; ++n, ++used) mean += points[indices[n]];
    if (used < 3) continue;
    mean /= static_cast<double>(used);
    Eigen::Matrix2d covariance = Eigen::Matrix2d::Zero();
    for (size_t n = 0; n < used; ++n) {
      const Eigen::Vector2d d = points[indices[n]] - mean;
      covariance += d * d.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> solver(covariance);
    if (!(solver.eigenvalues()(0) <= config.max_line_eigenvalue_ratio * solver.eigenvalues()(1))) continue;
    impl->normals[i] = solver.eigenvectors().col(0).normalized();
    keep[i] = true;
    ++line_like;
  }
  if (line_like == 0) return Error(fmt::format("planar ICP: none of the {} target points has a line-like neighbourhood", points.size()));
  // Sparse points that fit no line (far walls seen at a grazing angle) are dropped: matched
  // point-to-point they would hold a moving sensor back, as the scanner samples them at the
  // same angles from every pose.
  PlanarPoints kept;
  std::vector<Eigen::Vector2d> kept_normals;
  std::vector<Eigen::Vector3f> kept_lifted;
  for (size_t i = 0; i < points.size(); ++i) {
    if (!keep[i]) continue;
    kept.push_back(points[i]);
    kept_normals.push_back(impl->normals[i]);
    kept_lifted.push_back(lift(points[i]));
  }
  impl->points = std::move(kept);
  impl->normals = std::move(kept_normals);
  impl->tree = cloud::KdTree(std::move(kept_lifted));
  return PlanarTarget(std::move(impl));
}

namespace {

PlanarEquations linearize(const PlanarPoints& source, const PlanarTarget& target, const SE2& T, double gate, double huber_width) {
  PlanarEquations equations;
  const Eigen::Matrix2d R = T.rotation_matrix();
  const double gate_squared = gate * gate;
  for (const Eigen::Vector2d& p : source) {
    const Eigen::Vector2d q = R * p + T.translation();
    const long index = target.nearest(q, gate_squared, nullptr);
    if (index < 0) continue;
    const Eigen::Vector2d& normal = target.normals()[static_cast<size_t>(index)];
    const Eigen::Vector2d difference = q - target.points()[static_cast<size_t>(index)];
    // dq/d(x, y) = R, dq/dtheta = R (-p_y, p_x) for T Exp(delta) p.
    Eigen::Matrix<double, 2, 3> dq;
    dq.leftCols<2>() = R;
    dq.col(2) = R * Eigen::Vector2d(-p.y(), p.x());
    // Point-to-line where the target has a line, point-to-point elsewhere (corners, clutter:
    // what fixes the pose along a corridor).
    const bool on_line = !normal.isZero();
    const Eigen::Vector2d residual = on_line ? Eigen::Vector2d(normal.dot(difference), 0.0) : difference;
    Eigen::Matrix<double, 2, 3> jacobian = dq;
    if (on_line) {
      jacobian.row(0) = normal.transpose() * dq;
      jacobian.row(1).setZero();
    }
    const double magnitude = residual.norm();
    const double weight = magnitude <= huber_width ? 1.0 : huber_width / magnitude;
    equations.hessian += weight * jacobian.transpose() * jacobian;
    equations.gradient += weight * jacobian.transpose() * residual;
    equations.weighted_squared_residuals += weight * residual.squaredNorm();
    equations.squared_residuals += residual.squaredNorm();
    ++equations.correspondences;
  }
  return equations;
}

}  // namespace

double translation_constraint_ratio(const Eigen::Matrix3d& information, Eigen::Vector2d* weak_direction) {
  if (!(information(2, 2) > 0)) return 0.0;
  const Eigen::Matrix2d marginal =
      information.topLeftCorner<2, 2>() - information.topRightCorner<2, 1>() * information.bottomLeftCorner<1, 2>() / information(2, 2);
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> solver(marginal);
  if (weak_direction != nullptr) *weak_direction = solver.eigenvectors().col(0);
  if (!(solver.eigenvalues()(1) > 0)) return 0.0;
  return std::max(0.0, solver.eigenvalues()(0)) / solver.eigenvalues()(1);
}

Result<PlanarIcpResult> align_planar(const PlanarPoints& source, const PlanarTarget& target, const SE2& T_target_source_guess,
                                     const PlanarIcpConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  HANZO_RETURN_IF_ERROR(check_points(source, "source"));
  std::vector<double> gates;
  for (double gate : config.coarse_correspondence_distances) {
    if (gate > config.max_correspondence_distance) gates.push_back(gate);
  }
  gates.push_back(config.max_correspondence_distance);
  const double point_variance = config.point_sigma * config.point_sigma;
  Eigen::Vector3d prior_information = Eigen::Vector3d::Zero();
  if (config.guess_translation_sigma > 0) prior_information.head<2>().setConstant(1.0 / (config.guess_translation_sigma * config.guess_translation_sigma));
  if (config.guess_rotation_sigma > 0) prior_information(2) = 1.0 / (config.guess_rotation_sigma * config.guess_rotation_sigma);
  const SE2 guess_inverse = T_target_source_guess.inverse();
  // e = Log(guess^-1 T), de/dT = Jr^-1(e).
  auto add_prior = [&](const SE2& T, Eigen::Matrix3d* hessian, Eigen::Vector3d* gradient) {
    if (prior_information.isZero()) return;
    SE2::Jacobian jacobian;
    const Eigen::Vector3d error = (guess_inverse * T).log(&jacobian);
    *hessian += jacobian.transpose() * prior_information.asDiagonal() * jacobian;
    *gradient += jacobian.transpose() * prior_information.asDiagonal() * error;
  };
  PlanarIcpResult result;
  result.T_target_source = T_target_source_guess;
  PlanarEquations equations;
  for (size_t g = 0; g < gates.size(); ++g) {
    result.converged = false;
    for (int iteration = 0; iteration < config.max_iterations; ++iteration) {
      equations = linearize(source, target, result.T_target_source, gates[g], config.huber_width);
      if (equations.correspondences < 3) {
        return Error(fmt::format("planar ICP: {} of {} source points have a target point within {} m {}(need 3); "
                                 "check the initial guess and that the scans overlap",
                                 equations.correspondences, source.size(), gates[g],
                                 result.iterations == 0 ? "at the initial guess " : fmt::format("after {} iterations ", result.iterations)));
      }
      ++result.iterations;
      Eigen::Matrix3d hessian = equations.hessian / point_variance;
      Eigen::Vector3d gradient = equations.gradient / point_variance;
      add_prior(result.T_target_source, &hessian, &gradient);
      // A tiny damping keeps a degenerate direction (a corridor) from taking an unbounded step.
      hessian += 1e-6 * hessian.trace() * Eigen::Matrix3d::Identity();
      const Eigen::Vector3d step = -hessian.ldlt().solve(gradient);
      if (!step.allFinite()) return Error("planar ICP: the normal equations are singular");
      result.T_target_source = result.T_target_source * SE2::exp(step);
      if (step.head<2>().norm() < config.translation_tolerance && std::abs(step(2)) < config.rotation_tolerance) {
        result.converged = true;
        break;
      }
    }
  }
  equations = linearize(source, target, result.T_target_source, config.max_correspondence_distance, config.huber_width);
  result.num_correspondences = equations.correspondences;
  result.fitness = static_cast<double>(equations.correspondences) / static_cast<double>(source.size());
  if (equations.correspondences > 0) result.inlier_rmse = std::sqrt(equations.squared_residuals / static_cast<double>(equations.correspondences));
  // The a-posteriori residual variance, never below the assumed point_sigma^2.
  const double residual_variance =
      std::max(equations.weighted_squared_residuals / std::max<double>(1.0, static_cast<double>(equations.correspondences) - 3.0), point_variance);
  result.information = equations.hessian / residual_variance;
  Eigen::Vector3d unused_gradient = Eigen::Vector3d::Zero();
  add_prior(result.T_target_source, &result.information, &unused_gradient);
  result.hessian_eigenvalues = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(equations.hessian, Eigen::EigenvaluesOnly).eigenvalues();
  return result;
}

}  // namespace hanzo::fusion::lidar
