#pragma once
// VoxelHashMap: a sliding local map for LiDAR odometry and nearest-neighbour queries (the
// structure of KISS-ICP, Vizzo et al., RA-L 2023): points in a hash map of cubic voxels.
//
// - add(): each point goes to its voxel unless the voxel holds max_points_per_voxel points
//   or a point closer than min_point_spacing already (KISS-ICP >= 1.0's rule): voxels fill
//   with points spread over the surface instead of the first scan's ring, which matters for a
//   spinning LiDAR whose rings sample the ground in arcs. Then voxels whose centre lies
//   farther than max_distance from the sensor are dropped, so memory follows the sensor.
// - nearest() / nearest_k(): the nearest map points among the query's voxel and its 26
//   neighbours (exact within one voxel edge of the query).
//
// Frame and units: the map frame, metres. Voxel coordinates floor(p / voxel_size) must lie
// within +-2^20 per axis (+-524 km at 0.5 m); points outside are skipped and counted.
// Not thread-safe for writers; concurrent const queries are safe.

#include <cstdint>
#include <functional>
#include <vector>

#include <Eigen/Core>
#include <absl/container/flat_hash_map.h>

#include "hanzo/fusion/cloud/voxel_grid.hpp"

namespace hanzo::fusion::cloud {

/// A map point and the unit normal of the surface it was measured on (zero when unknown).
struct MapPoint {
  Eigen::Vector3f position = Eigen::Vector3f::Zero();
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();
};

struct VoxelHashMapConfig {
  double voxel_size = 0.5;         ///< m (spec: 0.1 indoor, 0.5 outdoor), > 0
  int max_points_per_voxel = 20;   ///< >= 1
  /// m: a point closer than this to one already in its voxel is not added; < 0: voxel_size /
  /// sqrt(max_points_per_voxel) (the spacing that fills a planar voxel evenly), 0: no rule.
  double min_point_spacing = -1.0;
  double max_distance = 100.0;     ///< m: voxels farther from the sensor are removed (> 0)
};

class VoxelHashMap {
 public:
  explicit VoxelHashMap(VoxelHashMapConfig config = {});

  /// Adds map-frame points (rules above, in the order given), then removes voxels farther than
  /// max_distance from `sensor_origin`. `normals`: empty, or one per point (zero when
  /// unknown). Non-finite points are skipped. The points are checked against the map on up to
  /// num_threads threads (parallel.hpp); the result is the same on any number.
  void add(const std::vector<Eigen::Vector3f>& points, const std::vector<Eigen::Vector3f>& normals,
           const Eigen::Vector3d& sensor_origin, int num_threads = 1);
  /// The same, asking normal_of(i) for the normal of points[i] only when the map does not
  /// already refuse the point (normals can be costly and most points of a scan fall into full
  /// or covered voxels). normal_of is called concurrently when num_threads != 1.
  void add(const std::vector<Eigen::Vector3f>& points, const Eigen::Vector3d& sensor_origin,
           const std::function<Eigen::Vector3f(std::size_t)>& normal_of, int num_threads = 1);
  void clear();

  /// The points of the voxel at `coordinates`, or nullptr when it is empty.
  const std::vector<MapPoint>* find(const Eigen::Vector3i& coordinates) const;
  Eigen::Vector3i coordinates(const Eigen::Vector3f& position) const { return voxel_coordinates(position, inverse_voxel_size_); }
  /// The nearest point to `query` among its voxel and the 26 around it.
  bool nearest(const Eigen::Vector3f& query, Eigen::Vector3f* point, float* squared_distance) const;
  /// Up to k nearest points within max_distance (m) of `query`, nearest first, into
  /// `neighbours` (cleared). max_distance beyond one voxel edge finds only those within it.
  void nearest_k(const Eigen::Vector3f& query, std::size_t k, float max_distance,
                 std::vector<MapPoint>* neighbours) const;

  /// Every point (unordered).
  std::vector<Eigen::Vector3f> points() const;
  std::size_t point_count() const { return point_count_; }
  std::size_t voxel_count() const { return voxels_.size(); }
  bool empty() const { return voxels_.empty(); }
  /// Points skipped because their voxel lies outside the key range (or they are not finite).
  std::size_t skipped_points() const { return skipped_points_; }
  /// Heap bytes held: hash table slots plus point storage (capacity).
  std::size_t memory_bytes() const;
  const VoxelHashMapConfig& config() const { return config_; }
  /// The minimum distance between points of a voxel in effect (m; see min_point_spacing).
  double point_spacing() const { return point_spacing_; }

 private:
  /// True when `voxel` is full or holds a point closer than the spacing to `point`.
  bool refuses(const std::vector<MapPoint>& voxel, const Eigen::Vector3f& point) const;
  /// Appends the point to its voxel (a non-finite normal stored as zero).
  void place(std::vector<MapPoint>& voxel, const Eigen::Vector3f& point, const Eigen::Vector3f& normal);
  /// add()'s insertion on several threads: the points the map refuses as it stands are found in
  /// parallel, the others placed in order.
  void add_in_parallel(const std::vector<Eigen::Vector3f>& points, const std::function<Eigen::Vector3f(std::size_t)>& normal_of,
                       int num_threads);
  /// Drops the voxels whose centre lies farther than max_distance from `sensor_origin`.
  void remove_farther_than(const Eigen::Vector3d& sensor_origin);

  VoxelHashMapConfig config_;
  float inverse_voxel_size_;
  double point_spacing_;
  float min_spacing_squared_;
  absl::flat_hash_map<uint64_t, std::vector<MapPoint>> voxels_;
  std::size_t point_count_ = 0;
  std::size_t skipped_points_ = 0;
};

}  // namespace hanzo::fusion::cloud
