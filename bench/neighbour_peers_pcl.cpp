#include <chrono>

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/octree/octree_search.h>
#include <pcl/point_types.h>

#include "neighbour_peers.hpp"

namespace bench {
namespace {

using Clock = std::chrono::steady_clock;
double milliseconds_since(Clock::time_point start) { return std::chrono::duration<double, std::milli>(Clock::now() - start).count(); }

pcl::PointCloud<pcl::PointXYZ>::Ptr to_pcl(const std::vector<Eigen::Vector3f>& points) {
  auto cloud = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  cloud->reserve(points.size());
  for (const Eigen::Vector3f& p : points) cloud->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  return cloud;
}

template <typename Search>
void query_all(Search& search, const std::vector<Eigen::Vector3f>& queries, int k, NeighbourTiming& timing) {
  std::vector<int> indices(static_cast<std::size_t>(k));
  std::vector<float> distances(static_cast<std::size_t>(k));
  const auto start = Clock::now();
  for (const Eigen::Vector3f& q : queries) {
    const int found = search.nearestKSearch(pcl::PointXYZ(q.x(), q.y(), q.z()), k, indices, distances);
    for (int i = 0; i < found; ++i) timing.squared_distance_sum += distances[static_cast<std::size_t>(i)];
  }
  timing.query_ms = milliseconds_since(start);
}

}  // namespace

NeighbourTiming pcl_octree_knn(const std::vector<Eigen::Vector3f>& map, const std::vector<Eigen::Vector3f>& queries, int k,
                               double resolution) {
  NeighbourTiming timing;
  const auto cloud = to_pcl(map);
  const auto start = Clock::now();
  pcl::octree::OctreePointCloudSearch<pcl::PointXYZ> octree(resolution);
  octree.setInputCloud(cloud);
  octree.addPointsFromInputCloud();
  timing.build_ms = milliseconds_since(start);
  query_all(octree, queries, k, timing);
  return timing;
}

NeighbourTiming pcl_kdtree_knn(const std::vector<Eigen::Vector3f>& map, const std::vector<Eigen::Vector3f>& queries, int k) {
  NeighbourTiming timing;
  const auto cloud = to_pcl(map);
  const auto start = Clock::now();
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(cloud);
  timing.build_ms = milliseconds_since(start);
  query_all(tree, queries, k, timing);
  return timing;
}

}  // namespace bench
