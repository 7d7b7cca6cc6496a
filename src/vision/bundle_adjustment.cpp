#include "hanzo/fusion/vision/bundle_adjustment.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include <Eigen/Cholesky>
#include <fmt/format.h>

namespace hanzo::fusion::vision {
namespace {

using Matrix6 = Eigen::Matrix<double, 6, 6>;
using Vector6 = Eigen::Matrix<double, 6, 1>;
using Matrix63 = Eigen::Matrix<double, 6, 3>;

// Ceres' trust-region constants (TrustRegionMinimizer, LevenbergMarquardtStrategy defaults).
constexpr double kMinRelativeDecrease = 1e-3;
constexpr double kMinDiagonal = 1e-6;
constexpr double kMaxDiagonal = 1e32;
constexpr double kMaxRadius = 1e16;
constexpr double kMinRadius = 1e-32;

double huber(double squared_norm, double threshold) {
  return squared_norm <= threshold * threshold ? squared_norm : 2.0 * threshold * std::sqrt(squared_norm) - threshold * threshold;
}

Status validate_problem(const BundleProblem& problem) {
  const auto poses = static_cast<int>(problem.T_world_body.size()), points = static_cast<int>(problem.points_world.size()),
             cameras = static_cast<int>(problem.cameras.size());
  if (problem.pose_fixed.size() != problem.T_world_body.size()) {
    return Error(fmt::format("bundle adjustment: {} fixed flags for {} poses", problem.pose_fixed.size(), poses), "pose_fixed");
  }
  for (int k = 0; k < poses; ++k) {
    if (!problem.T_world_body[static_cast<std::size_t>(k)].translation().allFinite()) return Error(fmt::format("bundle adjustment: pose {} is not finite", k), "T_world_body");
  }
  for (int j = 0; j < points; ++j) {
    if (!problem.points_world[static_cast<std::size_t>(j)].allFinite()) return Error(fmt::format("bundle adjustment: point {} is not finite", j), "points_world");
  }
  for (std::size_t i = 0; i < problem.observations.size(); ++i) {
    const BundleObservation& observation = problem.observations[i];
    if (observation.pose < 0 || observation.pose >= poses || observation.point < 0 || observation.point >= points || observation.camera < 0 ||
        observation.camera >= cameras) {
      return Error(fmt::format("bundle adjustment: observation {} names pose {}, point {}, camera {} of {}, {}, {}", i, observation.pose, observation.point,
                               observation.camera, poses, points, cameras),
                   "observations");
    }
    if (!(observation.sigma_px > 0.0) || !std::isfinite(observation.sigma_px) || !observation.pixel.allFinite()) {
      return Error(fmt::format("bundle adjustment: observation {}: sigma {} px or its pixel is not a positive finite number", i, observation.sigma_px),
                   "observations");
    }
  }
  return ok_status();
}

// A pose's and a camera's rotations as matrices (transposed) and translations: computed once
// per pose and camera for a pass over the observations.
struct Frames {
  Eigen::Matrix3d R_world_body_transpose;
  Eigen::Vector3d t_world_body;
  Eigen::Matrix3d R_body_camera_transpose;
  Eigen::Vector3d t_body_camera;
};

bool residual_at(const Frames& frames, const Eigen::Vector3d& p_world, const PinholeCamera& camera, const BundleObservation& observation,
                 Eigen::Vector2d& residual, Eigen::Matrix<double, 2, 6>* d_pose, Eigen::Matrix<double, 2, 3>* d_point) {
  const Eigen::Vector3d p_body = frames.R_world_body_transpose * (p_world - frames.t_world_body);
  const Eigen::Vector3d p_camera = frames.R_body_camera_transpose * (p_body - frames.t_body_camera);
  if (!(p_camera.z() > camera.min_depth)) return false;
  Eigen::Matrix<double, 2, 3> d_pixel;
  const bool with_jacobians = d_pose != nullptr || d_point != nullptr;
  const std::optional<Eigen::Vector2d> pixel = camera.project(p_camera, with_jacobians ? &d_pixel : nullptr);
  if (!pixel) return false;
  const double inverse_sigma = 1.0 / observation.sigma_px;
  residual = (*pixel - observation.pixel) * inverse_sigma;
  if (!with_jacobians) return true;
  const Eigen::Matrix<double, 2, 3> d_body = inverse_sigma * d_pixel * frames.R_body_camera_transpose;
  if (d_pose != nullptr) {
    d_pose->leftCols<3>() = -d_body;
    d_pose->rightCols<3>().noalias() = d_body * SO3::hat(p_body);
  }
  if (d_point != nullptr) d_point->noalias() = d_body * frames.R_world_body_transpose;
  return true;
}

// The solver's working state: the values, the observations grouped by point, and the normal
// equations' blocks at the last linearization point.
class Solver {
 public:
  Solver(const BundleProblem& problem, const BundleAdjustmentConfig& config) : problem_(problem), config_(config) {
    pose_slot_.assign(problem.T_world_body.size(), -1);
    for (std::size_t k = 0; k < problem.T_world_body.size(); ++k) {
      if (!problem.pose_fixed[k]) pose_slot_[k] = free_poses_++;
    }
    const std::size_t points = problem.points_world.size(), observations = problem.observations.size();
    point_begin_.assign(points + 1, 0);
    for (const BundleObservation& observation : problem.observations) ++point_begin_[static_cast<std::size_t>(observation.point) + 1];
    for (std::size_t j = 0; j < points; ++j) point_begin_[j + 1] += point_begin_[j];
    by_point_.resize(observations);
    std::vector<int> next(point_begin_.begin(), point_begin_.end() - 1);
    for (std::size_t i = 0; i < observations; ++i) by_point_[static_cast<std::size_t>(next[static_cast<std::size_t>(problem.observations[i].point)]++)] = static_cast<int>(i);
    for (Evaluation* evaluation : {&current_, &candidate_}) {
      evaluation->residual.resize(observations);
      evaluation->J_pose.resize(observations);
      evaluation->J_point.resize(observations);
    }
    H_pose_point_.resize(observations);
    H_pose_.resize(static_cast<std::size_t>(free_poses_));
    g_pose_.resize(static_cast<std::size_t>(free_poses_));
    H_point_.resize(points);
    g_point_.resize(points);
    point_inverse_.resize(points);
  }

  // Residuals and Jacobians of every observation at the values, into the candidate buffers, and
  // the cost 0.5 sum rho there; nullopt when an observation's point is behind its camera (its
  // index in `behind`). The Jacobians are computed with the residuals (a step is taken far more
  // often than refused, and the accepted step's linearization is then at hand).
  std::optional<double> evaluate(const std::vector<SE3>& poses, const std::vector<Eigen::Vector3d>& points, std::size_t* behind = nullptr) {
    set_frames(poses);
    double total = 0.0;
    for (std::size_t i = 0; i < problem_.observations.size(); ++i) {
      const BundleObservation& observation = problem_.observations[i];
      const bool free_pose = pose_slot_[static_cast<std::size_t>(observation.pose)] >= 0;
      if (!residual_at(frames_of(observation), points[static_cast<std::size_t>(observation.point)], problem_.cameras[static_cast<std::size_t>(observation.camera)].camera,
                       observation, candidate_.residual[i], free_pose ? &candidate_.J_pose[i] : nullptr, &candidate_.J_point[i])) {
        if (behind != nullptr) *behind = i;
        return std::nullopt;
      }
      total += 0.5 * huber(candidate_.residual[i].squaredNorm(), config_.huber_threshold);
    }
    return total;
  }

  // The candidate values become the current ones (their evaluation with them).
  void accept_candidate() { std::swap(current_, candidate_); }

  // The current residuals and Jacobians weighted by sqrt(rho') in place, and the normal
  // equations' blocks from them.
  void linearize() {
    std::fill(H_pose_.begin(), H_pose_.end(), Matrix6::Zero());
    std::fill(g_pose_.begin(), g_pose_.end(), Vector6::Zero());
    std::fill(H_point_.begin(), H_point_.end(), Eigen::Matrix3d::Zero());
    std::fill(g_point_.begin(), g_point_.end(), Eigen::Vector3d::Zero());
    const double threshold = config_.huber_threshold;
    for (std::size_t i = 0; i < problem_.observations.size(); ++i) {
      const BundleObservation& observation = problem_.observations[i];
      const auto j = static_cast<std::size_t>(observation.point);
      const int slot = pose_slot_[static_cast<std::size_t>(observation.pose)];
      Eigen::Vector2d& residual = current_.residual[i];
      Eigen::Matrix<double, 2, 6>& J_pose = current_.J_pose[i];
      Eigen::Matrix<double, 2, 3>& J_point = current_.J_point[i];
      const double squared_norm = residual.squaredNorm();
      if (squared_norm > threshold * threshold) {
        const double root_weight = std::sqrt(threshold / std::sqrt(squared_norm));
        residual *= root_weight;
        J_point *= root_weight;
        if (slot >= 0) J_pose *= root_weight;
      }
      H_point_[j].noalias() += J_point.transpose() * J_point;
      g_point_[j].noalias() += J_point.transpose() * residual;
      if (slot < 0) continue;
      const auto s = static_cast<std::size_t>(slot);
      H_pose_[s].noalias() += J_pose.transpose() * J_pose;
      g_pose_[s].noalias() += J_pose.transpose() * residual;
      H_pose_point_[i].noalias() = J_pose.transpose() * J_point;
    }
  }

  // Ceres' Jacobi scaling, 1 / (1 + column norm), from the first linearization.
  void set_scaling() {
    pose_scale_.resize(H_pose_.size());
    point_scale_.resize(H_point_.size());
    for (std::size_t s = 0; s < H_pose_.size(); ++s) pose_scale_[s] = (1.0 + H_pose_[s].diagonal().array().sqrt()).inverse().matrix();
    for (std::size_t j = 0; j < H_point_.size(); ++j) point_scale_[j] = (1.0 + H_point_[j].diagonal().array().sqrt()).inverse().matrix();
  }

  // The damped step (poses' tangent steps by slot, points' steps) by the Schur complement;
  // false when the reduced system or a point's block is not positive definite.
  bool solve(double radius, std::vector<Vector6>& pose_step, std::vector<Eigen::Vector3d>& point_step) {
    const auto damped = [radius](const auto& diagonal, const auto& scale) {
      const auto scaled = (diagonal.array() * scale.array().square()).max(kMinDiagonal).min(kMaxDiagonal);
      return (scaled / (radius * scale.array().square())).matrix().eval();
    };
    const int size = 6 * free_poses_;
    Eigen::MatrixXd reduced = Eigen::MatrixXd::Zero(size, size);
    Eigen::VectorXd right_side(size);
    for (int s = 0; s < free_poses_; ++s) {
      const auto slot = static_cast<std::size_t>(s);
      reduced.block<6, 6>(6 * s, 6 * s) = H_pose_[slot];
      reduced.block<6, 6>(6 * s, 6 * s).diagonal() += damped(H_pose_[slot].diagonal(), pose_scale_[slot]);
      right_side.segment<6>(6 * s) = -g_pose_[slot];
    }
    for (std::size_t j = 0; j + 1 < point_begin_.size(); ++j) {
      Eigen::Matrix3d H_point = H_point_[j];
      H_point.diagonal() += damped(H_point_[j].diagonal(), point_scale_[j]);
      Eigen::Matrix3d& inverse = point_inverse_[j];
      bool invertible = false;
      H_point.computeInverseWithCheck(inverse, invertible, 1e-300);
      if (!invertible || !inverse.allFinite()) return false;
      // This point's blocks by free pose (a pose seeing it through two cameras: one block).
      gathered_.clear();
      for (int at = point_begin_[j]; at < point_begin_[j + 1]; ++at) {
        const auto i = static_cast<std::size_t>(by_point_[static_cast<std::size_t>(at)]);
        const int slot = pose_slot_[static_cast<std::size_t>(problem_.observations[i].pose)];
        if (slot < 0) continue;
        const auto found = std::find_if(gathered_.begin(), gathered_.end(), [slot](const auto& entry) { return entry.first == slot; });
        if (found != gathered_.end()) {
          found->second += H_pose_point_[i];
        } else {
          gathered_.emplace_back(slot, H_pose_point_[i]);
        }
      }
      const Eigen::Vector3d inverse_gradient = inverse * g_point_[j];
      for (std::size_t a = 0; a < gathered_.size(); ++a) {
        const Matrix63 M = gathered_[a].second * inverse;
        const int row = 6 * gathered_[a].first;
        right_side.segment<6>(row).noalias() += gathered_[a].second * inverse_gradient;
        for (std::size_t b = 0; b < gathered_.size(); ++b) {
          const int column = 6 * gathered_[b].first;
          if (column < row) continue;
          reduced.block<6, 6>(row, column).noalias() -= M * gathered_[b].second.transpose();
        }
      }
    }
    Eigen::VectorXd pose_solution = Eigen::VectorXd::Zero(size);
    if (size > 0) {
      const Eigen::LDLT<Eigen::MatrixXd, Eigen::Upper> factor(reduced);
      if (factor.info() != Eigen::Success || !factor.isPositive()) return false;
      pose_solution = factor.solve(right_side);
      if (!pose_solution.allFinite()) return false;
    }
    pose_step.resize(static_cast<std::size_t>(free_poses_));
    for (int s = 0; s < free_poses_; ++s) pose_step[static_cast<std::size_t>(s)] = pose_solution.segment<6>(6 * s);
    point_step.resize(H_point_.size());
    for (std::size_t j = 0; j + 1 < point_begin_.size(); ++j) {
      Eigen::Vector3d right = -g_point_[j];
      for (int at = point_begin_[j]; at < point_begin_[j + 1]; ++at) {
        const auto i = static_cast<std::size_t>(by_point_[static_cast<std::size_t>(at)]);
        const int slot = pose_slot_[static_cast<std::size_t>(problem_.observations[i].pose)];
        if (slot >= 0) right.noalias() -= H_pose_point_[i].transpose() * pose_step[static_cast<std::size_t>(slot)];
      }
      point_step[j] = point_inverse_[j] * right;
    }
    return true;
  }

  // The linear model's cost decrease for the step: -(J dx)^T (r + J dx / 2) over the observations.
  double model_decrease(const std::vector<Vector6>& pose_step, const std::vector<Eigen::Vector3d>& point_step) const {
    double decrease = 0.0;
    for (std::size_t i = 0; i < problem_.observations.size(); ++i) {
      const BundleObservation& observation = problem_.observations[i];
      Eigen::Vector2d change = current_.J_point[i] * point_step[static_cast<std::size_t>(observation.point)];
      const int slot = pose_slot_[static_cast<std::size_t>(observation.pose)];
      if (slot >= 0) change.noalias() += current_.J_pose[i] * pose_step[static_cast<std::size_t>(slot)];
      decrease -= change.dot(current_.residual[i] + 0.5 * change);
    }
    return decrease;
  }

  int pose_slot(std::size_t pose) const { return pose_slot_[pose]; }

 private:
  // frames_[pose * cameras + camera] for the values passed.
  void set_frames(const std::vector<SE3>& poses) {
    const std::size_t cameras = problem_.cameras.size();
    frames_.resize(poses.size() * cameras);
    for (std::size_t k = 0; k < poses.size(); ++k) {
      for (std::size_t c = 0; c < cameras; ++c) {
        const SE3& T_body_camera = problem_.cameras[c].T_body_camera;
        frames_[k * cameras + c] = {poses[k].rotation().matrix().transpose(), poses[k].translation(), T_body_camera.rotation().matrix().transpose(),
                                    T_body_camera.translation()};
      }
    }
  }
  const Frames& frames_of(const BundleObservation& observation) const {
    return frames_[static_cast<std::size_t>(observation.pose) * problem_.cameras.size() + static_cast<std::size_t>(observation.camera)];
  }

  std::vector<Frames> frames_;
  const BundleProblem& problem_;
  const BundleAdjustmentConfig& config_;
  std::vector<int> pose_slot_;  // -1: fixed
  int free_poses_ = 0;
  std::vector<int> point_begin_, by_point_;  // observations by point (by_point_[point_begin_[j] .. point_begin_[j + 1]))
  // Per observation: the residual and its Jacobians (the pose's only for a free pose); current_
  // weighted by sqrt(rho') once linearized.
  struct Evaluation {
    std::vector<Eigen::Vector2d> residual;
    std::vector<Eigen::Matrix<double, 2, 6>> J_pose;
    std::vector<Eigen::Matrix<double, 2, 3>> J_point;
  };
  Evaluation current_, candidate_;
  std::vector<Matrix63> H_pose_point_;  // per observation of a free pose
  std::vector<Matrix6> H_pose_;
  std::vector<Vector6> g_pose_, pose_scale_;
  std::vector<Eigen::Matrix3d> H_point_, point_inverse_;
  std::vector<Eigen::Vector3d> g_point_, point_scale_;
  std::vector<std::pair<int, Matrix63>> gathered_;
};

}  // namespace

Status validate(const BundleAdjustmentConfig& config) {
  if (config.max_iterations < 0) return Error("BundleAdjustmentConfig.max_iterations: must not be negative", "max_iterations");
  if (!(config.huber_threshold > 0.0) || !std::isfinite(config.huber_threshold)) {
    return Error("BundleAdjustmentConfig.huber_threshold: must be a positive number", "huber_threshold");
  }
  if (!(config.initial_trust_region_radius > 0.0) || !std::isfinite(config.initial_trust_region_radius)) {
    return Error("BundleAdjustmentConfig.initial_trust_region_radius: must be a positive number", "initial_trust_region_radius");
  }
  if (!(config.function_tolerance >= 0.0) || !(config.parameter_tolerance >= 0.0)) {
    return Error("BundleAdjustmentConfig: function_tolerance and parameter_tolerance must not be negative", "function_tolerance");
  }
  return ok_status();
}

bool bundle_residual(const SE3& T_world_body, const Eigen::Vector3d& p_world, const BundleCamera& camera, const BundleObservation& observation,
                     Eigen::Vector2d& residual, Eigen::Matrix<double, 2, 6>* d_pose, Eigen::Matrix<double, 2, 3>* d_point) {
  const Frames frames{T_world_body.rotation().matrix().transpose(), T_world_body.translation(), camera.T_body_camera.rotation().matrix().transpose(),
                      camera.T_body_camera.translation()};
  return residual_at(frames, p_world, camera.camera, observation, residual, d_pose, d_point);
}

Result<BundleAdjustmentSummary> bundle_adjust(BundleProblem& problem, const BundleAdjustmentConfig& config) {
  HANZO_RETURN_IF_ERROR(validate(config));
  HANZO_RETURN_IF_ERROR(validate_problem(problem));
  Solver solver(problem, config);
  std::vector<SE3> poses = problem.T_world_body;
  std::vector<Eigen::Vector3d> points = problem.points_world;
  std::size_t behind = 0;
  const std::optional<double> initial = solver.evaluate(poses, points, &behind);
  if (!initial) {
    const BundleObservation& observation = problem.observations[behind];
    return Error(fmt::format("bundle adjustment: observation {}: point {} is behind camera {} of pose {}", behind, observation.point, observation.camera,
                             observation.pose),
                 "observations");
  }
  solver.accept_candidate();
  BundleAdjustmentSummary summary;
  summary.initial_cost = summary.final_cost = *initial;
  double cost = *initial, radius = config.initial_trust_region_radius, decrease_factor = 2.0;
  bool linearized = false;
  std::vector<Vector6> pose_step;
  std::vector<Eigen::Vector3d> point_step;
  std::vector<SE3> candidate_poses;
  std::vector<Eigen::Vector3d> candidate_points;
  while (summary.iterations < config.max_iterations) {
    if (!linearized) {
      solver.linearize();
      if (summary.iterations == 0) solver.set_scaling();
      linearized = true;
    }
    ++summary.iterations;
    bool step_taken = false;
    if (solver.solve(radius, pose_step, point_step)) {
      double step_norm = 0.0, value_norm = 0.0;
      for (const Vector6& step : pose_step) step_norm += step.squaredNorm();
      for (const Eigen::Vector3d& step : point_step) step_norm += step.squaredNorm();
      for (const SE3& pose : poses) value_norm += pose.translation().squaredNorm() + 1.0;  // a unit quaternion
      for (const Eigen::Vector3d& point : points) value_norm += point.squaredNorm();
      if (std::sqrt(step_norm) <= config.parameter_tolerance * (std::sqrt(value_norm) + config.parameter_tolerance)) {
        summary.converged = true;
        break;
      }
      candidate_poses = poses;
      for (std::size_t k = 0; k < poses.size(); ++k) {
        const int slot = solver.pose_slot(k);
        if (slot >= 0) candidate_poses[k] = poses[k] * SE3::exp(pose_step[static_cast<std::size_t>(slot)]);
      }
      candidate_points = points;
      for (std::size_t j = 0; j < points.size(); ++j) candidate_points[j] += point_step[j];
      const std::optional<double> candidate_cost = solver.evaluate(candidate_poses, candidate_points);
      if (candidate_cost) {
        const double cost_change = cost - *candidate_cost;
        if (std::abs(cost_change) <= config.function_tolerance * cost) {
          summary.converged = true;
          break;
        }
        const double model = solver.model_decrease(pose_step, point_step);
        const double relative_decrease = model > 0.0 ? cost_change / model : -1.0;
        if (relative_decrease > kMinRelativeDecrease) {
          poses.swap(candidate_poses);
          points.swap(candidate_points);
          solver.accept_candidate();
          cost = *candidate_cost;
          radius = std::min(kMaxRadius, radius / std::max(1.0 / 3.0, 1.0 - std::pow(2.0 * relative_decrease - 1.0, 3)));
          decrease_factor = 2.0;
          linearized = false;
          step_taken = true;
          ++summary.successful_steps;
        }
      }
    }
    if (!step_taken) {
      radius /= decrease_factor;
      decrease_factor *= 2.0;
      if (radius < kMinRadius) break;
    }
  }
  problem.T_world_body = std::move(poses);
  problem.points_world = std::move(points);
  summary.final_cost = cost;
  return summary;
}

}  // namespace hanzo::fusion::vision
