#pragma once
// The point map (spec, "LiDAR SLAM / Map representation: voxelized point cloud"): keyframe
// scans kept in their own sensor frame with their world poses, merged into one voxelized world
// cloud on demand. When the backend moves keyframes (a loop closure), set_poses() and the next
// cloud() rebuild the map from the corrected poses: no point is ever baked into a wrong place.
//
// Each voxel of the merged cloud becomes one point: the centroid of the points that fell in it,
// their mean intensity, and their spread as the per-point uncertainty
// (position_std = sqrt(trace(covariance) / 3), at least voxel_size / sqrt(12) / 2, the
// quantization of a voxel's centroid).

#include <cstddef>
#include <cstdint>
#include <map>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct PointMapConfig {
  /// Voxel edge of the merged map (m). Spec defaults: 0.1 indoor, 0.5 outdoor.
  double voxel_size = 0.1;
  /// Keyframe clouds are downsampled to this voxel edge (m) when added, to bound memory;
  /// 0 uses voxel_size / 2.
  double keyframe_voxel_size = 0.0;

  Status validate() const;
};

class PointMap {
 public:
  explicit PointMap(const PointMapConfig& config);
  static Result<PointMap> create(const PointMapConfig& config);

  /// Adds (or replaces) keyframe `id`: `cloud_in_sensor_frame` seen from `T_world_sensor`.
  /// Rejects invalid clouds and non-finite poses, changing nothing.
  Status add_keyframe(uint64_t id, const SE3& T_world_sensor, const cloud::PointCloud& cloud_in_sensor_frame);
  /// Moves keyframes (after optimization); every id must exist, else nothing changes.
  Status set_poses(const std::map<uint64_t, SE3>& T_world_sensor_by_id);
  Result<SE3> pose(uint64_t id) const;

  /// The voxelized world cloud (positions and, when every keyframe has them, intensities).
  /// Rebuilt only when keyframes changed since the last call.
  const cloud::PointCloud& cloud() const;
  /// The map as a FusionMap point layer (with per-point uncertainty).
  msgs::PointLayer to_layer() const;

  std::size_t keyframe_count() const { return keyframes_.size(); }
  /// Bytes held by the keyframe clouds and the merged map.
  std::size_t memory_bytes() const;
  const PointMapConfig& config() const { return config_; }

 private:
  struct Keyframe {
    SE3 T_world_sensor;
    cloud::PointCloud cloud;  // sensor frame, downsampled
  };
  void rebuild() const;

  PointMapConfig config_;
  std::map<uint64_t, Keyframe> keyframes_;
  mutable bool dirty_ = false;
  mutable cloud::PointCloud merged_;
  mutable std::vector<float> merged_std_;
};

}  // namespace hanzo::fusion::maps
