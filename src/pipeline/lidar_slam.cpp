#include "hanzo/fusion/pipeline/lidar_slam.hpp"

#include <chrono>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/cloud/voxel_hash_map.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"
#include "hanzo/fusion/lidar/surface_registration.hpp"

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
  HANZO_RETURN_IF_ERROR(with_context(scan_context.validate(), "scan_context"));
  if (!(keyframe_distance > 0)) return Error(fmt::format("keyframe_distance: {} <= 0", keyframe_distance));
  if (!(keyframe_angle > 0)) return Error(fmt::format("keyframe_angle: {} <= 0", keyframe_angle));
  for (const auto& [name, value] : {std::pair{"min_translation_sigma", min_translation_sigma}, {"min_rotation_sigma", min_rotation_sigma},
                                    {"loop_translation_sigma", loop_translation_sigma}, {"loop_rotation_sigma", loop_rotation_sigma},
                                    {"loop_max_rmse", loop_max_rmse}, {"loop_dcs_phi", loop_dcs_phi},
                                    {"loop_min_search_radius", loop_min_search_radius}}) {
    if (!(value > 0)) return Error(fmt::format("{}: {} <= 0", name, value));
  }
  if (!(translation_sigma_per_meter >= 0) || !(rotation_sigma_per_meter >= 0) || !(loop_search_radius_per_meter >= 0)) {
    return Error("translation_sigma_per_meter, rotation_sigma_per_meter, loop_search_radius_per_meter: must be >= 0");
  }
  if (!(loop_min_travel >= 0)) return Error(fmt::format("loop_min_travel: {} < 0", loop_min_travel));
  if (loop_submap_keyframes < 0) return Error(fmt::format("loop_submap_keyframes: {} < 0", loop_submap_keyframes));
  if (!(loop_min_inlier_fraction >= 0 && loop_min_inlier_fraction <= 1)) {
    return Error(fmt::format("loop_min_inlier_fraction: {} outside [0, 1]", loop_min_inlier_fraction));
  }
  return ok_status();
}

LidarSlam::LidarSlam(LidarSlamConfig config, const SE3& initial_pose)
    : config_(std::move(config)), odometry_(config_.odometry, initial_pose), scan_contexts_(config_.scan_context) {}

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
  keyframes_.push_back({estimate.T_world_lidar, odometry_.last_scan_points(), path_});
  ++summary_.keyframes;
  cloud::PointCloud points;
  points.positions = keyframes_.back().points;
  auto descriptor = lidar::make_scan_context(points, config_.scan_context);
  if (!descriptor) return descriptor.error();
  HANZO_RETURN_IF_ERROR(scan_contexts_.add(k, std::move(*descriptor)));
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

Result<SE3> LidarSlam::verify(std::size_t candidate, std::size_t newest, const SE3& guess) const {
  // The submap around the candidate in the candidate's frame, at two resolutions: 3 m voxels
  // (neighbours within 3 m) pull in a guess metres off, the odometry's map resolution refines.
  const cloud::VoxelHashMapConfig& fine_config = config_.odometry.map;
  cloud::VoxelHashMap coarse({.voxel_size = 3.0 * fine_config.voxel_size, .max_points_per_voxel = 4 * fine_config.max_points_per_voxel,
                              .min_point_spacing = -1.0, .max_distance = 1e6});
  cloud::VoxelHashMap fine({.voxel_size = fine_config.voxel_size, .max_points_per_voxel = fine_config.max_points_per_voxel,
                            .min_point_spacing = fine_config.min_point_spacing, .max_distance = 1e6});
  const SE3 T_candidate_inverse = keyframe_pose(candidate).inverse();
  const std::size_t half = static_cast<std::size_t>(config_.loop_submap_keyframes);
  const std::size_t first = candidate >= half ? candidate - half : 0;
  const std::size_t last = std::min(newest - 1, candidate + half);
  for (std::size_t j = first; j <= last; ++j) {
    const SE3 T = T_candidate_inverse * keyframe_pose(j);
    cloud::PointCloud keyframe;
    keyframe.positions = keyframes_[j].points;
    const std::vector<Eigen::Vector3f> points = cloud::transformed(keyframe, T).positions;
    coarse.add(points, {}, T.translation());
    fine.add(points, {}, T.translation());
  }
  cloud::PointCloud scan;
  scan.positions = keyframes_[newest].points;
  const std::vector<Eigen::Vector3f> source = cloud::voxel_downsample(scan, config_.odometry.source_voxel_size).positions;
  lidar::SurfaceRegistrationConfig registration = config_.odometry.registration;
  registration.prior_translation_sigma = 10.0;  // the guess may be metres off after a long loop
  registration.prior_rotation_sigma = 1.0;
  registration.max_iterations = 40;
  lidar::SurfaceRegistrationConfig coarse_registration = registration;
  coarse_registration.max_neighbour_distance = 3.0 * fine_config.voxel_size;
  coarse_registration.initial_kernel_width = 2.0;
  coarse_registration.kernel_width = 0.3;
  coarse_registration.max_correspondence_distance = 1.0;
  lidar::SurfaceRegistrationResult pulled_in, result;
  HANZO_ASSIGN_OR_RETURN(pulled_in, lidar::align_to_surfaces(source, coarse, guess, guess, coarse_registration));
  HANZO_ASSIGN_OR_RETURN(result, lidar::align_to_surfaces(source, fine, pulled_in.T_map_source, pulled_in.T_map_source, registration));
  const double inliers = static_cast<double>(result.correspondences) / static_cast<double>(source.size());
  if (!result.converged || result.inlier_rmse > config_.loop_max_rmse || inliers < config_.loop_min_inlier_fraction ||
      lidar::translation_constraint_ratio(result.information) < config_.odometry.degeneracy_ratio) {
    return Error(fmt::format("not verified: converged {}, inlier RMSE {:.3f} m, {:.0f} % matched", result.converged,
                             result.inlier_rmse, 100.0 * inliers));
  }
  return result.T_map_source;
}

bool LidarSlam::close_loop() {
  const std::size_t newest = keyframes_.size() - 1;
  cloud::PointCloud points;
  points.positions = keyframes_[newest].points;
  auto descriptor = lidar::make_scan_context(points, config_.scan_context);
  if (!descriptor) return false;
  auto match = scan_contexts_.query(*descriptor);
  if (!match || !*match) return false;
  const std::size_t candidate = static_cast<std::size_t>((*match)->id);
  if (keyframes_[newest].path - keyframes_[candidate].path < config_.loop_min_travel) return false;
  // From the graph's relative pose (right when the drift is small), else from the descriptor's
  // yaw with the positions taken as equal.
  const SE3 from_graph = keyframe_pose(candidate).inverse() * keyframe_pose(newest);
  const double travelled = keyframes_[newest].path - keyframes_[candidate].path;
  if (from_graph.translation().norm() > config_.loop_min_search_radius + config_.loop_search_radius_per_meter * travelled) return false;
  const SE3 from_descriptor(SO3::exp(Eigen::Vector3d(0, 0, (*match)->distance.yaw)), Eigen::Vector3d::Zero());
  ++summary_.loop_candidates;
  Result<SE3> verified = verify(candidate, newest, from_graph);
  if (!verified) verified = verify(candidate, newest, from_descriptor);
  if (!verified) {
    logger()->debug("lidar SLAM: loop {} -> {} rejected: {}", candidate, newest, verified.error().message);
    return false;
  }
  auto noise = pose_noise(config_.loop_translation_sigma, config_.loop_rotation_sigma);
  if (!noise) return false;
  graph_.emplace_robust<graph::BetweenFactorSE3>(graph::RobustKernel{graph::RobustKernel::Type::kDcs, config_.loop_dcs_phi},
                                                 graph::X(candidate), graph::X(newest), *verified, std::move(*noise));
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
