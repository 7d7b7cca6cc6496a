#include "hanzo/fusion/maps/point_map.hpp"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::maps {

Status PointMapConfig::validate() const {
  if (!(std::isfinite(voxel_size) && voxel_size > 0.0)) {
    return Error{fmt::format("point_map.voxel_size: must be a positive number of meters, got {}", voxel_size), "voxel_size"};
  }
  if (!(std::isfinite(keyframe_voxel_size) && keyframe_voxel_size >= 0.0)) {
    return Error{fmt::format("point_map.keyframe_voxel_size: must be >= 0 meters, got {}", keyframe_voxel_size),
                 "keyframe_voxel_size"};
  }
  return ok_status();
}

PointMap::PointMap(const PointMapConfig& config) : config_(config) {}

Result<PointMap> PointMap::create(const PointMapConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  return PointMap(config);
}

Status PointMap::add_keyframe(uint64_t id, const SE3& T_world_sensor, const cloud::PointCloud& cloud_in_sensor_frame) {
  if (!T_world_sensor.matrix().allFinite()) return Error{fmt::format("keyframe {}: pose is not finite", id), "T_world_sensor"};
  HANZO_RETURN_IF_ERROR(with_context(cloud_in_sensor_frame.validate(), fmt::format("keyframe {}", id)));
  const double keyframe_voxel = config_.keyframe_voxel_size > 0.0 ? config_.keyframe_voxel_size : config_.voxel_size / 2.0;
  cloud::PointCloud kept = cloud::voxel_downsample(cloud_in_sensor_frame, keyframe_voxel);
  // Only what the map uses.
  kept.rings.clear();
  kept.times.clear();
  kept.normals.clear();
  kept.covariances.clear();
  keyframes_[id] = Keyframe{T_world_sensor, std::move(kept)};
  dirty_ = true;
  return ok_status();
}

Status PointMap::set_poses(const std::map<uint64_t, SE3>& T_world_sensor_by_id) {
  for (const auto& [id, pose] : T_world_sensor_by_id) {
    if (!keyframes_.contains(id)) return Error{fmt::format("set_poses: no keyframe {}", id), "id"};
    if (!pose.matrix().allFinite()) return Error{fmt::format("set_poses: keyframe {} pose is not finite", id), "T_world_sensor"};
  }
  for (const auto& [id, pose] : T_world_sensor_by_id) keyframes_[id].T_world_sensor = pose;
  dirty_ = dirty_ || !T_world_sensor_by_id.empty();
  return ok_status();
}

Result<SE3> PointMap::pose(uint64_t id) const {
  const auto found = keyframes_.find(id);
  if (found == keyframes_.end()) return Error{fmt::format("no keyframe {}", id), "id"};
  return found->second.T_world_sensor;
}

void PointMap::rebuild() const {
  struct Voxel {
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    double sum_squared_norm = 0.0;
    double intensity_sum = 0.0;
    uint32_t count = 0;
  };
  const bool with_intensity = !keyframes_.empty() && std::all_of(keyframes_.begin(), keyframes_.end(), [](const auto& entry) {
    return entry.second.cloud.has_intensities() || entry.second.cloud.empty();
  });
  const float inverse_voxel = static_cast<float>(1.0 / config_.voxel_size);
  std::unordered_map<uint64_t, Voxel> voxels;
  std::size_t dropped = 0;
  for (const auto& [id, keyframe] : keyframes_) {
    const Eigen::Matrix3d rotation = keyframe.T_world_sensor.rotation().matrix();
    const Eigen::Vector3d translation = keyframe.T_world_sensor.translation();
    for (std::size_t i = 0; i < keyframe.cloud.size(); ++i) {
      const Eigen::Vector3d world = rotation * keyframe.cloud.positions[i].cast<double>() + translation;
      uint64_t key = 0;
      if (!cloud::pack_voxel_key(cloud::voxel_coordinates(world.cast<float>(), inverse_voxel), &key)) {
        ++dropped;
        continue;
      }
      Voxel& voxel = voxels[key];
      voxel.sum += world;
      voxel.sum_squared_norm += world.squaredNorm();
      if (with_intensity) voxel.intensity_sum += keyframe.cloud.intensities[i];
      ++voxel.count;
    }
  }
  if (dropped > 0) logger()->warn("point map: {} points outside the voxel key range were left out", dropped);

  std::vector<std::pair<uint64_t, const Voxel*>> ordered;
  ordered.reserve(voxels.size());
  for (const auto& [key, voxel] : voxels) ordered.emplace_back(key, &voxel);
  std::sort(ordered.begin(), ordered.end(), [](const auto& a, const auto& b) { return a.first < b.first; });

  merged_.clear();
  merged_std_.clear();
  merged_.positions.reserve(ordered.size());
  merged_std_.reserve(ordered.size());
  if (with_intensity) merged_.intensities.reserve(ordered.size());
  const double quantization_std = config_.voxel_size / std::sqrt(12.0) / 2.0;
  for (const auto& [key, voxel] : ordered) {
    const Eigen::Vector3d mean = voxel->sum / voxel->count;
    const double variance = std::max(0.0, voxel->sum_squared_norm / voxel->count - mean.squaredNorm()) / 3.0;
    merged_.positions.push_back(mean.cast<float>());
    merged_std_.push_back(static_cast<float>(std::max(std::sqrt(variance), quantization_std)));
    if (with_intensity) merged_.intensities.push_back(static_cast<float>(voxel->intensity_sum / voxel->count));
  }
  dirty_ = false;
}

const cloud::PointCloud& PointMap::cloud() const {
  if (dirty_) rebuild();
  return merged_;
}

msgs::PointLayer PointMap::to_layer() const {
  const cloud::PointCloud& merged = cloud();
  msgs::PointLayer layer;
  layer.points = merged.positions;
  layer.position_std = merged_std_;
  layer.intensities = merged.intensities;
  layer.voxel_size = config_.voxel_size;
  return layer;
}

std::size_t PointMap::memory_bytes() const {
  std::size_t bytes = merged_.positions.capacity() * sizeof(Eigen::Vector3f) + merged_.intensities.capacity() * sizeof(float) +
                      merged_std_.capacity() * sizeof(float);
  for (const auto& [id, keyframe] : keyframes_) {
    bytes += sizeof(Keyframe) + keyframe.cloud.positions.capacity() * sizeof(Eigen::Vector3f) +
             keyframe.cloud.intensities.capacity() * sizeof(float);
  }
  return bytes;
}

}  // namespace hanzo::fusion::maps
