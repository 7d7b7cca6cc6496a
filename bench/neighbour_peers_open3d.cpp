#include <chrono>

#include <open3d/geometry/KDTreeFlann.h>
#include <open3d/geometry/PointCloud.h>

#include "neighbour_peers.hpp"

namespace bench {

NeighbourTiming open3d_kdtree_knn(const std::vector<Eigen::Vector3f>& map, const std::vector<Eigen::Vector3f>& queries, int k) {
  using Clock = std::chrono::steady_clock;
  NeighbourTiming timing;
  open3d::geometry::PointCloud cloud;
  cloud.points_.reserve(map.size());
  for (const Eigen::Vector3f& p : map) cloud.points_.push_back(p.cast<double>());
  auto start = Clock::now();
  const open3d::geometry::KDTreeFlann tree(cloud);
  timing.build_ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  std::vector<int> indices;
  std::vector<double> distances;
  start = Clock::now();
  for (const Eigen::Vector3f& q : queries) {
    const int found = tree.SearchKNN(Eigen::Vector3d(q.cast<double>()), k, indices, distances);
    for (int i = 0; i < found; ++i) timing.squared_distance_sum += distances[static_cast<std::size_t>(i)];
  }
  timing.query_ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  return timing;
}

}  // namespace bench
