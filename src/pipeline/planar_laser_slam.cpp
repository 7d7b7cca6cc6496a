#include "hanzo/fusion/pipeline/planar_laser_slam.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <Eigen/Cholesky>
#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

Eigen::Matrix3d sigma_floor(double translation_sigma, double rotation_sigma) {
  return Eigen::Vector3d(translation_sigma * translation_sigma, translation_sigma * translation_sigma, rotation_sigma * rotation_sigma)
      .asDiagonal();
}

// The matcher's covariance (its information inverted; a direction it does not constrain gets a
// large variance) plus a floor.
Eigen::Matrix3d match_covariance(const Eigen::Matrix3d& information, const Eigen::Matrix3d& floor) {
  const Eigen::Matrix3d regularized = information + 1e-4 * Eigen::Matrix3d::Identity();
  return regularized.ldlt().solve(Eigen::Matrix3d::Identity()) + floor;
}

}  // namespace

Status PlanarLaserSlamConfig::validate() const {
  HANZO_RETURN_IF_ERROR(with_context(scan_matching.validate(), "scan_matching"));
  HANZO_RETURN_IF_ERROR(with_context(recovery_search.validate(), "recovery_search"));
  HANZO_RETURN_IF_ERROR(with_context(loop_search.validate(), "loop_search"));
  if (min_scan_points < 3) return Error(fmt::format("min_scan_points: {} < 3", min_scan_points));
  if (!(keyframe_distance > 0) || !(keyframe_rotation > 0)) return Error("keyframe_distance / keyframe_rotation must be > 0");
  if (local_map_keyframes < 1) return Error(fmt::format("local_map_keyframes: {} < 1", local_map_keyframes));
  if (!(min_translation_sigma > 0) || !(min_rotation_sigma > 0) || !(loop_translation_sigma > 0) || !(loop_rotation_sigma > 0)) {
    return Error("the minimum and loop-closure sigmas must be > 0");
  }
  if (!(loop_min_linear_window >= 0) || !(loop_linear_window_per_meter >= 0) || !(loop_min_angular_window >= 0) || !(loop_angular_window_per_meter >= 0)) {
    return Error("the loop-closure window settings must be >= 0");
  }
  if (loop_candidates < 0 || loop_submap_keyframes < 0) return Error("loop_candidates / loop_submap_keyframes must be >= 0");
  if (!(loop_dcs_phi > 0)) return Error(fmt::format("loop_dcs_phi: {} <= 0", loop_dcs_phi));
  if (optimization_iterations < 1) return Error(fmt::format("optimization_iterations: {} < 1", optimization_iterations));
  return {};
}

PlanarLaserSlam::PlanarLaserSlam(PlanarLaserSlamConfig config) : config_(std::move(config)) {}

SE2 PlanarLaserSlam::keyframe_pose(size_t index) const { return values_.at<SE2>(graph::X(index)).value(); }

Result<lidar::PlanarTarget> PlanarLaserSlam::local_map_target() const {
  lidar::PlanarPoints points;
  const size_t first = keyframes_.size() > static_cast<size_t>(config_.local_map_keyframes) ? keyframes_.size() - static_cast<size_t>(config_.local_map_keyframes) : 0;
  for (size_t k = first; k < keyframes_.size(); ++k) {
    const SE2 pose = keyframe_pose(k);
    for (const Eigen::Vector2d& p : keyframes_[k].points_laser) points.push_back(pose * p);
  }
  return lidar::PlanarTarget::create(std::move(points), config_.scan_matching);
}

PlanarLaserSlam::Match PlanarLaserSlam::match_scan(const lidar::PlanarPoints& points, const SE2& guess, double travelled) {
  Match match;
  match.T_map_laser = guess;
  if (!local_map_) {
    auto target = local_map_target();
    if (!target) {
      logger()->warn("planar laser SLAM: no local map ({}); placing the scan by odometry", target.error().message);
      return match;
    }
    local_map_ = std::move(*target);
  }
  auto accept = [&](const Result<lidar::PlanarIcpResult>& result) {
    if (!result || result->fitness < config_.min_scan_matching_fitness) return false;
    match.T_map_laser = result->T_target_source;
    match.covariance = match_covariance(result->information, sigma_floor(config_.min_translation_sigma, config_.min_rotation_sigma));
    match.matched = true;
    match.fitness = result->fitness;
    match.constraint_ratio = lidar::translation_constraint_ratio(result->information);
    return true;
  };
  bool accepted = accept(lidar::align_planar(points, *local_map_, guess, config_.scan_matching));
  if (!accepted) {
    auto searched = lidar::correlative_scan_match(points, local_map_->points(), guess, config_.recovery_search);
    accepted = searched && accept(lidar::align_planar(points, *local_map_, searched->T_target_source, config_.scan_matching));
    if (accepted) ++summary_.recovered_matches;
  }
  if (accepted && match.constraint_ratio < config_.degeneracy_ratio) {
    // A corridor: hold the free direction at the odometry prediction.
    lidar::PlanarIcpConfig with_prior = config_.scan_matching;
    with_prior.guess_translation_sigma = config_.min_translation_sigma + config_.odometry_translation_sigma_per_meter * travelled;
    with_prior.guess_rotation_sigma = config_.min_rotation_sigma + config_.odometry_rotation_sigma_per_meter * travelled;
    if (accept(lidar::align_planar(points, *local_map_, guess, with_prior))) {
      match.degenerate = true;
      ++summary_.degenerate_scans;
    }
  }
  return match;
}

Status PlanarLaserSlam::add_keyframe(Timestamp time, const lidar::PlanarPoints& points, const Match& match, double path_length) {
  const size_t index = keyframes_.size();
  if (index > 0) {
    const SE2 relative = keyframe_pose(index - 1).inverse() * match.T_map_laser;
    Eigen::Matrix3d covariance = match.covariance;
    if (!match.matched) {
      const double distance = relative.translation().norm();
      covariance = sigma_floor(config_.min_translation_sigma + config_.odometry_translation_sigma_per_meter * distance,
                               config_.min_rotation_sigma + config_.odometry_rotation_sigma_per_meter * distance + 0.1 * std::abs(relative.angle()));
    }
    graph::GaussianNoise noise;
    HANZO_ASSIGN_OR_RETURN(noise, graph::GaussianNoise::from_covariance(covariance));
    graph_.emplace<graph::BetweenFactorSE2>(graph::X(index - 1), graph::X(index), relative, std::move(noise));
  }
  values_.insert(graph::X(index), match.T_map_laser);
  keyframes_.push_back({time, points, path_length});
  local_map_.reset();
  ++summary_.keyframes;
  return {};
}

int PlanarLaserSlam::close_loops() {
  const size_t newest = keyframes_.size() - 1;
  const SE2 T_map_newest = keyframe_pose(newest);
  const double newest_path = keyframes_[newest].path_length;
  auto far_enough_back = [&](size_t k) { return newest_path - keyframes_[k].path_length >= config_.loop_min_travel; };
  std::vector<std::pair<double, size_t>> candidates;
  for (size_t k = 0; k < newest && far_enough_back(k); ++k) {
    const double distance = (keyframe_pose(k).translation() - T_map_newest.translation()).norm();
    if (distance <= config_.loop_search_radius) candidates.emplace_back(distance, k);
  }
  std::sort(candidates.begin(), candidates.end());
  if (candidates.size() > static_cast<size_t>(config_.loop_candidates)) candidates.resize(static_cast<size_t>(config_.loop_candidates));
  const double drift_path = newest_path - path_length_at_last_loop_closure_;
  lidar::CorrelativeScanMatcherConfig search = config_.loop_search;
  search.linear_window = std::min(search.linear_window, config_.loop_min_linear_window + config_.loop_linear_window_per_meter * drift_path);
  search.angular_window = std::min(search.angular_window, config_.loop_min_angular_window + config_.loop_angular_window_per_meter * drift_path);
  int added = 0;
  for (const auto& [distance, candidate] : candidates) {
    ++summary_.loop_candidates;
    // The candidate's submap in its own frame (keyframes far enough back only).
    const SE2 T_candidate_map = keyframe_pose(candidate).inverse();
    lidar::PlanarPoints submap;
    const size_t first = candidate > static_cast<size_t>(config_.loop_submap_keyframes) ? candidate - static_cast<size_t>(config_.loop_submap_keyframes) : 0;
    for (size_t k = first; k <= candidate + static_cast<size_t>(config_.loop_submap_keyframes) && k < newest; ++k) {
      if (!far_enough_back(k)) continue;
      const SE2 T_candidate_k = T_candidate_map * keyframe_pose(k);
      for (const Eigen::Vector2d& p : keyframes_[k].points_laser) submap.push_back(T_candidate_k * p);
    }
    const lidar::PlanarPoints& scan = keyframes_[newest].points_laser;
    const SE2 guess = T_candidate_map * T_map_newest;
    auto searched = lidar::correlative_scan_match(scan, submap, guess, search);
    if (!searched) continue;
    auto target = lidar::PlanarTarget::create(std::move(submap), config_.scan_matching);
    if (!target) continue;
    auto refined = lidar::align_planar(scan, *target, searched->T_target_source, config_.scan_matching);
    if (!refined || !refined->converged || refined->fitness < config_.loop_min_fitness || refined->inlier_rmse > config_.loop_max_inlier_rmse) {
      continue;
    }
    auto noise = graph::GaussianNoise::from_covariance(
        match_covariance(refined->information, sigma_floor(config_.loop_translation_sigma, config_.loop_rotation_sigma)));
    if (!noise) continue;
    graph_.emplace_robust<graph::BetweenFactorSE2>(graph::RobustKernel{graph::RobustKernel::Type::kDcs, config_.loop_dcs_phi},
                                                   graph::X(candidate), graph::X(newest), refined->T_target_source, std::move(*noise));
    ++added;
    ++summary_.loop_closures;
  }
  if (added > 0) path_length_at_last_loop_closure_ = newest_path;
  return added;
}

Status PlanarLaserSlam::optimize(int max_iterations) {
  graph::BatchOptimizerConfig batch;
  batch.max_iterations = max_iterations;
  batch.fixed = {graph::X(0)};
  graph::OptimizationSummary result;
  HANZO_ASSIGN_OR_RETURN(result, graph::optimize(graph_, values_, batch));
  ++summary_.optimizations;
  summary_.final_chi2 = result.final_chi2;
  summary_.optimization_seconds += result.seconds;
  local_map_.reset();
  return {};
}

Result<PlanarScanEstimate> PlanarLaserSlam::add_scan(Timestamp time, const lidar::PlanarPoints& points_laser, const SE2& T_odom_laser) {
  HANZO_RETURN_IF_ERROR(config_.validate());
  if (!scans_.empty() && time <= scans_.back().time) {
    return Error(fmt::format("planar laser SLAM: scan time {} s does not increase (last {} s)", time.seconds(), scans_.back().time.seconds()));
  }
  if (points_laser.size() < static_cast<size_t>(config_.min_scan_points)) {
    return Error(fmt::format("planar laser SLAM: the scan has {} points (need {})", points_laser.size(), config_.min_scan_points));
  }
  for (const Eigen::Vector2d& p : points_laser) {
    if (!p.allFinite()) return Error("planar laser SLAM: the scan has a non-finite point");
  }
  if (!T_odom_laser.translation().allFinite() || !std::isfinite(T_odom_laser.angle())) return Error("planar laser SLAM: the odometry pose is not finite");

  PlanarScanEstimate estimate;
  if (scans_.empty()) {
    T_odom_last_ = T_odom_laser;
    Match first;
    first.T_map_laser = T_odom_laser;
    first.matched = true;
    HANZO_RETURN_IF_ERROR(add_keyframe(time, points_laser, first, 0.0));
    scans_.push_back({time, 0, SE2()});
    T_map_last_ = T_odom_laser;
    ++summary_.scans;
    estimate.T_map_laser = T_odom_laser;
    estimate.T_map_laser_matched = T_odom_laser;
    estimate.keyframe = true;
    estimate.scan_matched = true;
    return estimate;
  }

  const SE2 increment = T_odom_last_.inverse() * T_odom_laser;
  const double path_length = path_length_ + increment.translation().norm();
  const auto match_start = Clock::now();
  const Match match = match_scan(points_laser, T_map_last_ * increment, increment.translation().norm());
  summary_.scan_matching_seconds += seconds_since(match_start);
  if (!match.matched) ++summary_.unmatched_scans;

  const SE2 from_keyframe = keyframe_pose(keyframes_.size() - 1).inverse() * match.T_map_laser;
  const bool new_keyframe = from_keyframe.translation().norm() >= config_.keyframe_distance || std::abs(from_keyframe.angle()) >= config_.keyframe_rotation;
  if (new_keyframe) {
    HANZO_RETURN_IF_ERROR(add_keyframe(time, points_laser, match, path_length));
    if (config_.loop_closure) {
      const auto loop_start = Clock::now();
      estimate.loop_closures_added = close_loops();
      summary_.loop_closure_seconds += seconds_since(loop_start);
      if (estimate.loop_closures_added > 0) HANZO_RETURN_IF_ERROR(optimize(config_.optimization_iterations));
    }
  }
  path_length_ = path_length;
  T_odom_last_ = T_odom_laser;
  const size_t keyframe = keyframes_.size() - 1;
  const SE2 T_keyframe_laser = new_keyframe ? SE2() : from_keyframe;
  scans_.push_back({time, keyframe, T_keyframe_laser});
  T_map_last_ = keyframe_pose(keyframe) * T_keyframe_laser;
  ++summary_.scans;
  estimate.T_map_laser = T_map_last_;
  estimate.T_map_laser_matched = match.T_map_laser;
  estimate.covariance = match.covariance;
  estimate.keyframe = new_keyframe;
  estimate.keyframe_index = keyframe;
  estimate.scan_matched = match.matched;
  estimate.degenerate = match.degenerate;
  estimate.fitness = match.fitness;
  return estimate;
}

Result<PlanarScanEstimate> PlanarLaserSlam::add_scan(const msgs::PointCloudMessage& scan, const SE2& T_odom_laser) {
  lidar::PlanarPoints points;
  points.reserve(scan.points.size());
  for (const Eigen::Vector3f& point : scan.points) points.emplace_back(point.x(), point.y());
  return add_scan(scan.timestamp, points, T_odom_laser);
}

Status PlanarLaserSlam::finish() {
  if (keyframes_.size() < 2) return {};
  return optimize(100);
}

io::Trajectory PlanarLaserSlam::trajectory() const {
  io::Trajectory trajectory;
  for (const ScanRecord& scan : scans_) {
    trajectory.timestamps.push_back(scan.time);
    trajectory.poses.push_back(io::pose_matrix(keyframe_pose(scan.keyframe) * scan.T_keyframe_laser));
  }
  return trajectory;
}

}  // namespace hanzo::fusion::pipeline
