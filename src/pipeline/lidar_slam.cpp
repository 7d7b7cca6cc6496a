#include "hanzo/fusion/pipeline/lidar_slam.hpp"

#include <chrono>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

Result<graph::GaussianNoise> pose_noise(double translation_sigma, double rotation_sigma) {
  Eigen::VectorXd sigmas(6);
  sigmas << Eigen::Vector3d::Constant(translation_sigma), Eigen::Vector3d::Constant(rotation_sigma);
  return graph::GaussianNoise::from_sigmas(sigmas);
}

}  // namespace

Status LidarSlamConfig::validate() const {
  HANZO_RETURN_IF_ERROR(with_context(odometry.validate(), "odometry"));
  HANZO_RETURN_IF_ERROR(with_context(loop.validate(), "loop"));
  if (!(keyframe_distance > 0)) return Error(fmt::format("keyframe_distance: {} <= 0", keyframe_distance));
  if (!(keyframe_angle > 0)) return Error(fmt::format("keyframe_angle: {} <= 0", keyframe_angle));
  for (const auto& [name, value] : {std::pair{"min_translation_sigma", min_translation_sigma}, {"min_rotation_sigma", min_rotation_sigma},
                                    {"loop_translation_sigma", loop_translation_sigma}, {"loop_rotation_sigma", loop_rotation_sigma},
                                    {"loop_dcs_phi", loop_dcs_phi}}) {
    if (!(value > 0)) return Error(fmt::format("{}: {} <= 0", name, value));
  }
  if (!(translation_sigma_per_meter >= 0) || !(rotation_sigma_per_meter >= 0)) {
    return Error("translation_sigma_per_meter, rotation_sigma_per_meter: must be >= 0");
  }
  return ok_status();
}

LidarSlam::LidarSlam(LidarSlamConfig config, const SE3& initial_pose)
    : config_(std::move(config)), odometry_(config_.odometry, initial_pose), loop_closures_(config_.loop, config_.odometry) {}

SE3 LidarSlam::keyframe_pose(std::size_t k) const { return values_.at<SE3>(graph::X(k)).value(); }

Result<lidar::LidarOdometryEstimate> LidarSlam::add_scan(Timestamp time, const cloud::PointCloud& scan) {
  HANZO_RETURN_IF_ERROR(with_context(config_.validate(), "lidar SLAM config"));
  const auto started = Clock::now();
  const SE3 previous = odometry_.pose();
  lidar::LidarOdometryEstimate estimate;
  HANZO_ASSIGN_OR_RETURN(estimate, odometry_.add_scan(time, scan));
  summary_.odometry_seconds += seconds_since(started);
  ++summary_.scans;
  if (!sweeps_.empty()) path_ += (previous.inverse() * estimate.T_world_lidar).translation().norm();

  bool keyframe = keyframes_.empty();
  if (!keyframe) {
    const SE3 since = keyframes_.back().T_odometry.inverse() * estimate.T_world_lidar;
    keyframe = since.translation().norm() >= config_.keyframe_distance || since.rotation().log().norm() >= config_.keyframe_angle;
  }
  if (keyframe) HANZO_RETURN_IF_ERROR(add_keyframe(estimate));
  sweeps_.push_back({estimate.time, estimate.T_world_lidar, keyframes_.size() - 1});
  return estimate;
}

Status LidarSlam::add_keyframe(const lidar::LidarOdometryEstimate& estimate) {
  const std::size_t k = keyframes_.size();
  if (k == 0) {
    values_.insert(graph::X(0), estimate.T_world_lidar);
  } else {
    // The odometry's motion since the last keyframe, on top of that keyframe's optimized pose.
    const SE3 relative = keyframes_.back().T_odometry.inverse() * estimate.T_world_lidar;
    const double distance = relative.translation().norm();
    graph::GaussianNoise noise;
    HANZO_ASSIGN_OR_RETURN(noise, pose_noise(config_.min_translation_sigma + config_.translation_sigma_per_meter * distance,
                                             config_.min_rotation_sigma + config_.rotation_sigma_per_meter * distance));
    graph_.emplace<graph::BetweenFactorSE3>(graph::X(k - 1), graph::X(k), relative, std::move(noise));
    values_.insert(graph::X(k), keyframe_pose(k - 1) * relative);
  }
  keyframes_.push_back({estimate.T_world_lidar});
  ++summary_.keyframes;
  HANZO_RETURN_IF_ERROR(loop_closures_.add_keyframe(odometry_.last_scan_points(), path_));
  if (!config_.loop_closure) return ok_status();

  const auto loop_started = Clock::now();
  const bool closed = close_loop();
  summary_.loop_closure_seconds += seconds_since(loop_started);
  if (!closed) return ok_status();
  const auto optimization_started = Clock::now();
  graph::BatchOptimizerConfig batch;
  batch.fixed = {graph::X(0)};
  if (auto optimized = graph::optimize(graph_, values_, batch); !optimized) {
    logger()->warn("lidar SLAM: optimization after a loop closure failed: {}", optimized.error().message);
  } else {
    ++summary_.optimizations;
  }
  summary_.optimization_seconds += seconds_since(optimization_started);
  return ok_status();
}

bool LidarSlam::close_loop() {
  const std::optional<lidar::LoopClosure> loop = loop_closures_.detect([this](std::size_t k) { return keyframe_pose(k); });
  summary_.loop_candidates = loop_closures_.candidates();
  if (!loop) return false;
  auto noise = pose_noise(config_.loop_translation_sigma, config_.loop_rotation_sigma);
  if (!noise) return false;
  graph_.emplace_robust<graph::BetweenFactorSE3>(graph::RobustKernel{graph::RobustKernel::Type::kDcs, config_.loop_dcs_phi},
                                                 graph::X(loop->from), graph::X(loop->to), loop->T_from_to, std::move(*noise));
  ++summary_.loop_closures;
  return true;
}

io::Trajectory LidarSlam::trajectory() const {
  io::Trajectory out;
  for (const SweepRecord& sweep : sweeps_) {
    const Keyframe& keyframe = keyframes_[sweep.keyframe];
    out.timestamps.push_back(sweep.time);
    out.poses.push_back((keyframe_pose(sweep.keyframe) * keyframe.T_odometry.inverse() * sweep.T_odometry).matrix());
  }
  return out;
}

}  // namespace hanzo::fusion::pipeline
