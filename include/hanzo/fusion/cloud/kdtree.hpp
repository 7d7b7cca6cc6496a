#pragma once
// KdTree: exact nearest-neighbour queries over a fixed set of 3D points (nanoflann, leaf size
// 8). Built once in O(n log n); a query costs O(log n) on average. Indices refer to the order
// of the points given to the constructor. Queries are const and thread-safe.

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

namespace hanzo::fusion::cloud {

class KdTree {
 public:
  /// Builds the tree over a copy of `points` (m). An empty set is allowed: every query then
  /// finds nothing.
  explicit KdTree(std::vector<Eigen::Vector3f> points);
  ~KdTree();
  KdTree(KdTree&&) noexcept;
  KdTree& operator=(KdTree&&) noexcept;

  size_t size() const;
  const std::vector<Eigen::Vector3f>& points() const;

  /// The nearest point to `query` closer than sqrt(max_squared_distance); false when none is.
  bool nearest(const Eigen::Vector3f& query, float max_squared_distance, uint32_t* index,
               float* squared_distance) const;
  /// The min(k, size()) nearest points, closest first; returns how many were written.
  size_t knn(const Eigen::Vector3f& query, size_t k, uint32_t* indices, float* squared_distances) const;
  /// How many points lie within `radius` (m) of `query`, counting stops at `max_count`.
  size_t count_within(const Eigen::Vector3f& query, float radius, size_t max_count) const;
  /// Every point within `radius` (m) of `query`, closest first.
  void radius_search(const Eigen::Vector3f& query, float radius, std::vector<uint32_t>* indices,
                     std::vector<float>* squared_distances) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace hanzo::fusion::cloud
