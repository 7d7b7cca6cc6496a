#include "hanzo/fusion/lidar/loop_closure.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/cloud/voxel_hash_map.hpp"
#include "hanzo/fusion/lidar/surface_registration.hpp"

namespace hanzo::fusion::lidar {

Status LoopClosureConfig::validate() const {
  HANZO_RETURN_IF_ERROR(with_context(scan_context.validate(), "scan_context"));
  for (const auto& [name, value] : {std::pair{"max_rmse", max_rmse}, {"min_search_radius", min_search_radius}}) {
    if (!(value > 0)) return Error(fmt::format("{}: {} <= 0", name, value));
  }
  if (!(search_radius_per_meter >= 0)) return Error(fmt::format("search_radius_per_meter: {} < 0", search_radius_per_meter));
  if (!(min_travel >= 0)) return Error(fmt::format("min_travel: {} < 0", min_travel));
  if (!(covered_distance >= 0)) return Error(fmt::format("covered_distance: {} < 0", covered_distance));
  if (!(covered_angle >= 0)) return Error(fmt::format("covered_angle: {} < 0", covered_angle));
  if (!(covered_max_spacing >= 0)) return Error(fmt::format("covered_max_spacing: {} < 0", covered_max_spacing));
  if (submap_keyframes < 0) return Error(fmt::format("submap_keyframes: {} < 0", submap_keyframes));
  if (!(min_inlier_fraction >= 0 && min_inlier_fraction <= 1)) {
    return Error(fmt::format("min_inlier_fraction: {} outside [0, 1]", min_inlier_fraction));
  }
  return ok_status();
}

LoopClosureDetector::LoopClosureDetector(LoopClosureConfig config, LidarOdometryConfig odometry)
    : config_(std::move(config)), odometry_(std::move(odometry)), scan_contexts_(config_.scan_context) {}

Result<std::size_t> LoopClosureDetector::add_keyframe(std::vector<Eigen::Vector3f> points, double path) {
  if (!std::isfinite(path) || (!keyframes_.empty() && path < keyframes_.back().path)) {
    return Error(fmt::format("loop closure keyframe: path {} m is not finite or less than the previous keyframe's", path));
  }
  for (const Eigen::Vector3f& point : points) {
    if (!point.allFinite()) return Error("loop closure keyframe: a point is not finite");
  }
  cloud::PointCloud cloud;
  cloud.positions = std::move(points);
  ScanContext descriptor;
  HANZO_ASSIGN_OR_RETURN(descriptor, make_scan_context(cloud, config_.scan_context));
  const std::size_t k = keyframes_.size();
  HANZO_RETURN_IF_ERROR(scan_contexts_.add(k, descriptor));
  newest_descriptor_ = std::move(descriptor);
  keyframes_.push_back({std::move(cloud.positions), path});
  return k;
}

bool LoopClosureDetector::covered(const SE3& T_world_query, double path, const PoseLookup& T_world_keyframe) const {
  if (!(config_.covered_distance > 0)) return false;
  const Eigen::Vector3d query = T_world_query.translation();
  std::optional<SE3> previous;  // keyframe k - 1, when old enough
  for (std::size_t k = 0; k < keyframes_.size() && path - keyframes_[k].path >= config_.min_travel; ++k) {
    const SE3 T_world_keyframe_k = T_world_keyframe(k);
    const Eigen::Vector3d b = T_world_keyframe_k.translation();
    // The nearest point of the segment from keyframe k - 1 to k (or keyframe k itself).
    SE3 nearer = T_world_keyframe_k;
    Eigen::Vector3d nearest = b;
    if (previous && (b - previous->translation()).norm() <= config_.covered_max_spacing) {
      const Eigen::Vector3d a = previous->translation();
      const double length_squared = (b - a).squaredNorm();
      const double along = length_squared > 0 ? std::clamp((query - a).dot(b - a) / length_squared, 0.0, 1.0) : 1.0;
      nearest = a + along * (b - a);
      if (along < 0.5) nearer = *previous;
    }
    previous = T_world_keyframe_k;
    if ((query - nearest).norm() > config_.covered_distance) continue;
    if ((nearer.rotation().inverse() * T_world_query.rotation()).log().norm() <= config_.covered_angle) return true;
  }
  return false;
}

void LoopClosureDetector::remove_newest() {
  if (keyframes_.empty()) return;
  keyframes_.pop_back();
  scan_contexts_.remove_newest();
  newest_descriptor_.reset();
}

std::optional<LoopClosure> LoopClosureDetector::detect(const PoseLookup& T_world_keyframe) {
  if (keyframes_.empty() || !newest_descriptor_) return std::nullopt;
  const std::size_t newest = keyframes_.size() - 1;
  auto match = scan_contexts_.query(*newest_descriptor_);
  if (!match || !*match) return std::nullopt;
  const std::size_t candidate = static_cast<std::size_t>((*match)->id);
  const double travelled = keyframes_[newest].path - keyframes_[candidate].path;
  if (candidate >= newest || travelled < config_.min_travel) return std::nullopt;
  // From the estimate's relative pose (right when the drift is small), else from the
  // descriptor's yaw with the positions taken as equal.
  const SE3 from_estimate = T_world_keyframe(candidate).inverse() * T_world_keyframe(newest);
  if (from_estimate.translation().norm() > config_.min_search_radius + config_.search_radius_per_meter * travelled) return std::nullopt;
  const SE3 from_descriptor(SO3::exp(Eigen::Vector3d(0, 0, (*match)->distance.yaw)), Eigen::Vector3d::Zero());
  ++candidates_;
  Result<LoopClosure> verified = verify(candidate, newest, from_estimate, T_world_keyframe);
  if (!verified) verified = verify(candidate, newest, from_descriptor, T_world_keyframe);
  if (!verified) return std::nullopt;
  return *verified;
}

Result<SubmapRegistration> register_to_submap(const std::vector<SubmapKeyframe>& submap, const std::vector<Eigen::Vector3f>& query,
                                              const SE3& guess, const LoopClosureConfig& config, const LidarOdometryConfig& odometry) {
  if (!guess.matrix().allFinite()) return Error("the guess is not finite");
  // The submap at two resolutions: 3x coarser voxels (neighbours within 3 voxels) pull in a
  // guess metres off, the odometry's map resolution refines.
  const cloud::VoxelHashMapConfig& fine_config = odometry.map;
  cloud::VoxelHashMap coarse({.voxel_size = 3.0 * fine_config.voxel_size, .max_points_per_voxel = 4 * fine_config.max_points_per_voxel,
                              .min_point_spacing = -1.0, .max_distance = 1e6});
  cloud::VoxelHashMap fine({.voxel_size = fine_config.voxel_size, .max_points_per_voxel = fine_config.max_points_per_voxel,
                            .min_point_spacing = fine_config.min_point_spacing, .max_distance = 1e6});
  for (const SubmapKeyframe& keyframe : submap) {
    cloud::PointCloud cloud;
    cloud.positions = *keyframe.points;
    const std::vector<Eigen::Vector3f> points = cloud::transformed(cloud, keyframe.T_submap_keyframe).positions;
    coarse.add(points, {}, keyframe.T_submap_keyframe.translation());
    fine.add(points, {}, keyframe.T_submap_keyframe.translation());
  }
  cloud::PointCloud scan;
  scan.positions = query;
  const std::vector<Eigen::Vector3f> source = cloud::voxel_downsample(scan, odometry.source_voxel_size).positions;
  if (source.empty()) return Error("the query has no points");
  SurfaceRegistrationConfig registration = odometry.registration;
  registration.prior_translation_sigma = 10.0;  // the guess may be metres off after a long loop
  registration.prior_rotation_sigma = 1.0;
  registration.max_iterations = 40;
  SurfaceRegistrationConfig coarse_registration = registration;
  coarse_registration.max_neighbour_distance = 3.0 * fine_config.voxel_size;
  coarse_registration.initial_kernel_width = 2.0;
  coarse_registration.kernel_width = 0.3;
  coarse_registration.max_correspondence_distance = 1.0;
  SurfaceRegistrationResult pulled_in, result;
  HANZO_ASSIGN_OR_RETURN(pulled_in, align_to_surfaces(source, coarse, guess, guess, coarse_registration));
  HANZO_ASSIGN_OR_RETURN(result, align_to_surfaces(source, fine, pulled_in.T_map_source, pulled_in.T_map_source, registration));
  const double inliers = static_cast<double>(result.correspondences) / static_cast<double>(source.size());
  if (!result.converged || result.inlier_rmse > config.max_rmse || inliers < config.min_inlier_fraction ||
      translation_constraint_ratio(result.information) < odometry.degeneracy_ratio) {
    return Error(fmt::format("not verified: converged {}, inlier RMSE {:.3f} m (max {}), {:.0f} % matched (min {:.0f} %)", result.converged,
                             result.inlier_rmse, config.max_rmse, 100.0 * inliers, 100.0 * config.min_inlier_fraction));
  }
  return SubmapRegistration{.T_submap_query = result.T_map_source, .inlier_rmse = result.inlier_rmse, .inlier_fraction = inliers};
}

Result<LoopClosure> LoopClosureDetector::verify(std::size_t from, std::size_t to, const SE3& guess,
                                                const PoseLookup& T_world_keyframe) const {
  if (from >= keyframes_.size() || to >= keyframes_.size() || from == to) {
    return Error(fmt::format("loop closure {} -> {}: unknown keyframe (there are {})", from, to, keyframes_.size()));
  }
  // The submap around `from` in its frame: keyframes older than the query.
  std::vector<SubmapKeyframe> submap;
  const SE3 T_from_world = T_world_keyframe(from).inverse();
  const std::size_t half = static_cast<std::size_t>(config_.submap_keyframes);
  const std::size_t first = from >= half ? from - half : 0;
  const std::size_t last = std::min(keyframes_.size() - 1, from + half);
  for (std::size_t j = first; j <= last; ++j) {
    if (j >= to && from < to) break;
    if (j == to) continue;
    submap.push_back({&keyframes_[j].points, T_from_world * T_world_keyframe(j)});
  }
  const Result<SubmapRegistration> registered = register_to_submap(submap, keyframes_[to].points, guess, config_, odometry_);
  if (!registered) return Error(fmt::format("loop closure {} -> {}: {}", from, to, registered.error().message));
  return LoopClosure{.from = from, .to = to, .T_from_to = registered->T_submap_query, .inlier_rmse = registered->inlier_rmse,
                     .inlier_fraction = registered->inlier_fraction};
}

}  // namespace hanzo::fusion::lidar
