#pragma once
// The peer libraries of bench_nearest_neighbours behind plain functions (PCL and Open3D headers
// stay in their own translation units). Each builds its structure over `map` and answers the
// k nearest neighbours of every query; times in milliseconds.

#include <vector>

#include <Eigen/Core>

namespace bench {

struct NeighbourTiming {
  double build_ms = 0.0;
  double query_ms = 0.0;
  double squared_distance_sum = 0.0;  ///< over all neighbours found: the engines must agree
};

/// PCL 1.13 pcl::octree::OctreePointCloudSearch (leaf edge `resolution`).
NeighbourTiming pcl_octree_knn(const std::vector<Eigen::Vector3f>& map, const std::vector<Eigen::Vector3f>& queries, int k,
                               double resolution);
/// PCL 1.13 pcl::KdTreeFLANN.
NeighbourTiming pcl_kdtree_knn(const std::vector<Eigen::Vector3f>& map, const std::vector<Eigen::Vector3f>& queries, int k);
/// Open3D 0.16 open3d::geometry::KDTreeFlann.
NeighbourTiming open3d_kdtree_knn(const std::vector<Eigen::Vector3f>& map, const std::vector<Eigen::Vector3f>& queries, int k);

}  // namespace bench
