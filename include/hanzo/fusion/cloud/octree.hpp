#pragma once
// Octree: an incremental octree over 3D points for map nearest-neighbour queries (the
// structure of i-Octree, Zhu et al., ICRA 2024, simplified: leaves hold their points in buckets;
// no lazy deletion).
//
// - insert(): each point descends to its leaf; a leaf holding more than bucket_size points
//   splits into its 8 octants unless its edge is already min_leaf_size or less. A point closer
//   than min_point_spacing to one already in its leaf is not inserted (a map keeps one point per
//   spacing). Points outside the root cube grow it (the root doubles toward them, keeping the
//   existing tree as one octant), so a map can follow a sensor anywhere.
// - remove_outside(): drops every point farther than `radius` from `center` (a local map
//   sliding with the sensor); subtrees entirely outside are freed at once.
// - nearest() / knn() / radius_search(): exact, descending into octants nearest first and
//   skipping those whose box is farther than the current bound.
//
// Versus VoxelHashMap: exact k-nearest at any distance (the voxel map finds neighbours within one
// voxel edge only), adapts its cells to the point density; versus KdTree: inserting and removing
// points costs O(log n) each instead of a rebuild.
//
// Frame and units: the caller's, metres. Not thread-safe for writers; concurrent const queries
// are safe. Non-finite points are skipped and counted.

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::cloud {

struct OctreeConfig {
  std::size_t bucket_size = 32;    ///< points a leaf holds before it splits (>= 1)
  double min_leaf_size = 0.05;     ///< m: leaves this small never split (> 0)
  double min_point_spacing = 0.0;  ///< m: a point this close to one in its leaf is not inserted (0: all are)
  /// m: the root cube's edge at the first insertion (it grows as needed), > 0.
  double initial_size = 64.0;

  /// Ok, or an Error naming the first invalid field.
  Status validate() const;
};

class Octree {
 public:
  /// An invalid config (see validate()) is replaced by the defaults, with a warning logged.
  explicit Octree(OctreeConfig config = {});

  /// Inserts points (rules above); returns how many were inserted.
  std::size_t insert(const std::vector<Eigen::Vector3f>& points);
  /// Removes the points farther than `radius` (m) from `center`; returns how many.
  std::size_t remove_outside(const Eigen::Vector3f& center, float radius);
  void clear();

  /// The nearest point to `query` within sqrt(max_squared_distance); false when there is none.
  bool nearest(const Eigen::Vector3f& query, float max_squared_distance, Eigen::Vector3f* point, float* squared_distance) const;
  /// Up to k nearest points within sqrt(max_squared_distance) (default: any distance), nearest
  /// first; `points` and `squared_distances` are cleared first (the latter may be null).
  void knn(const Eigen::Vector3f& query, std::size_t k, std::vector<Eigen::Vector3f>* points,
           std::vector<float>* squared_distances = nullptr,
           float max_squared_distance = std::numeric_limits<float>::infinity()) const;
  /// Every point within `radius` (m) of `query`, nearest first.
  void radius_search(const Eigen::Vector3f& query, float radius, std::vector<Eigen::Vector3f>* points,
                     std::vector<float>* squared_distances = nullptr) const;

  std::size_t size() const { return point_count_; }
  bool empty() const { return point_count_ == 0; }
  /// Every point (unordered).
  std::vector<Eigen::Vector3f> points() const;
  std::size_t node_count() const { return nodes_.size() - free_nodes_.size() * 8; }
  /// Points skipped because they were not finite.
  std::size_t skipped_points() const { return skipped_points_; }
  /// Heap bytes held: nodes and point buckets (capacity).
  std::size_t memory_bytes() const;
  const OctreeConfig& config() const { return config_; }

 private:
  static constexpr uint32_t kNone = 0xFFFFFFFFU;
  struct Node {
    Eigen::Vector3f center = Eigen::Vector3f::Zero();
    float half_size = 0.0F;
    uint32_t first_child = kNone;  ///< index of 8 consecutive children, or kNone for a leaf
    std::vector<Eigen::Vector3f> points;  ///< a leaf's bucket
  };

  void grow_to(const Eigen::Vector3f& point);
  bool insert_point(const Eigen::Vector3f& point);
  void split(uint32_t node);
  uint32_t allocate_children(const Node& parent);
  void free_subtree(uint32_t node);
  std::size_t remove_outside(uint32_t node, const Eigen::Vector3f& center, float squared_radius);
  template <typename Visit>
  void search(uint32_t node, const Eigen::Vector3f& query, float& bound, Visit& visit) const;

  OctreeConfig config_;
  std::vector<Node> nodes_;          ///< nodes_[0] is the root once a point was inserted
  std::vector<uint32_t> free_nodes_; ///< first indices of freed 8-child blocks, for reuse
  std::size_t point_count_ = 0;
  std::size_t skipped_points_ = 0;
};

}  // namespace hanzo::fusion::cloud
