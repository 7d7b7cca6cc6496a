#include <open3d/pipelines/registration/GlobalOptimization.h>
#include <open3d/pipelines/registration/GlobalOptimizationConvergenceCriteria.h>
#include <open3d/pipelines/registration/GlobalOptimizationMethod.h>
#include <open3d/pipelines/registration/PoseGraph.h>

#include "graph_peers.hpp"

namespace hanzo::fusion::bench {

void open3d_optimize_pose_graph(std::vector<Eigen::Matrix4d>& poses, const std::vector<Open3dEdge>& edges) {
  namespace registration = open3d::pipelines::registration;
  registration::PoseGraph graph;
  for (const Eigen::Matrix4d& pose : poses) graph.nodes_.emplace_back(pose);
  // Open3D's edge residual is X^-1 T_target^-1 T_source: source = `to`, target = `from`.
  for (const Open3dEdge& edge : edges) graph.edges_.emplace_back(edge.to, edge.from, edge.measurement, edge.information, false, 1.0);
  registration::GlobalOptimization(graph, registration::GlobalOptimizationLevenbergMarquardt(),
                                   registration::GlobalOptimizationConvergenceCriteria(),
                                   registration::GlobalOptimizationOption(0.075, 0.25, 1.0, 0));
  for (std::size_t i = 0; i < poses.size(); ++i) poses[i] = graph.nodes_[i].pose_;
}

}  // namespace hanzo::fusion::bench
