#pragma once
// Open3D 0.16's pose-graph optimization (pipelines::registration::GlobalOptimization,
// Levenberg-Marquardt) behind a small interface, so that Open3D's headers stay out of
// bench_graph.cpp. Poses are 4x4 T_world_node; an edge measures node `to` in the frame of node
// `from` (g2o's convention), information 6x6 in Open3D's order (rotation, translation).

#include <vector>

#include <Eigen/Core>

namespace hanzo::fusion::bench {

struct Open3dEdge {
  int from = 0;
  int to = 0;
  Eigen::Matrix4d measurement = Eigen::Matrix4d::Identity();
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Identity();
};

/// Optimizes the poses in place with node 0 as the reference.
void open3d_optimize_pose_graph(std::vector<Eigen::Matrix4d>& poses, const std::vector<Open3dEdge>& edges);

}  // namespace hanzo::fusion::bench
