#include "similarity_pose_graph.hpp"

#include <cmath>

#include <ceres/ceres.h>
#include <Eigen/Geometry>

namespace hanzo::fusion::vision {
namespace {

// Residual of one edge over (q_from, t_from, ln s_from, q_to, t_to, ln s_to).
struct SimilarityEdgeResidual {
  SimilarityEdgeResidual(const Similarity& measured, double weight) : measured_(measured), weight_(weight) {}

  template <typename T>
  bool operator()(const T* q_from_data, const T* t_from_data, const T* log_s_from, const T* q_to_data, const T* t_to_data, const T* log_s_to,
                  T* residual_data) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q_from(q_from_data), q_to(q_to_data);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t_from(t_from_data), t_to(t_to_data);
    // S_from^-1 S_to: R_from^T R_to, R_from^T (t_to - t_from) / s_from, s_to / s_from.
    const Eigen::Quaternion<T> q_from_inverse = q_from.conjugate();
    const Eigen::Quaternion<T> q_estimated = q_from_inverse * q_to;
    const Eigen::Matrix<T, 3, 1> t_estimated = (q_from_inverse * (t_to - t_from)) * ceres::exp(-log_s_from[0]);
    const Eigen::Quaternion<T> q_error = measured_.rotation.conjugate().cast<T>() * q_estimated;
    Eigen::Map<Eigen::Matrix<T, 7, 1>> residual(residual_data);
    // Shortest rotation: q and -q are the same rotation.
    const T sign = q_error.w() < T(0) ? T(-2) : T(2);
    residual.template head<3>() = sign * q_error.vec() * T(weight_);
    residual.template segment<3>(3) = (t_estimated - measured_.translation.cast<T>()) * T(weight_);
    residual[6] = (log_s_to[0] - log_s_from[0] - T(std::log(measured_.scale))) * T(weight_);
    return true;
  }

 private:
  Similarity measured_;
  double weight_;
};

}  // namespace

SimilarityPoseGraphSummary optimize_similarity_pose_graph(std::map<int, Similarity>& S_world_node, const std::vector<SimilarityEdge>& edges,
                                                          const std::set<int>& fixed, bool fix_scale, int max_iterations) {
  struct Block {
    Eigen::Vector4d quaternion;  // x, y, z, w (Eigen's storage order)
    Eigen::Vector3d translation;
    double log_scale;
  };
  std::map<int, Block> blocks;
  for (const auto& [node, pose] : S_world_node) {
    blocks[node] = {pose.rotation.normalized().coeffs(), pose.translation, std::log(pose.scale)};
  }
  ceres::Problem problem;  // owns the cost functions and the manifold
  std::set<int> used;
  for (const SimilarityEdge& edge : edges) {
    if (!blocks.count(edge.from) || !blocks.count(edge.to)) continue;
    Block& from = blocks[edge.from];
    Block& to = blocks[edge.to];
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<SimilarityEdgeResidual, 7, 4, 3, 1, 4, 3, 1>(new SimilarityEdgeResidual(edge.S_from_to, edge.weight)),
                             nullptr, from.quaternion.data(), from.translation.data(), &from.log_scale, to.quaternion.data(), to.translation.data(),
                             &to.log_scale);
    used.insert(edge.from);
    used.insert(edge.to);
  }
  SimilarityPoseGraphSummary summary;
  if (used.empty()) return summary;
  auto* quaternion_manifold = new ceres::EigenQuaternionManifold();
  for (int node : used) {
    Block& block = blocks[node];
    problem.SetManifold(block.quaternion.data(), quaternion_manifold);
    if (fixed.count(node)) {
      problem.SetParameterBlockConstant(block.quaternion.data());
      problem.SetParameterBlockConstant(block.translation.data());
    }
    if (fixed.count(node) || fix_scale) problem.SetParameterBlockConstant(&block.log_scale);
  }
  ceres::Solver::Options options;
  options.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  options.max_num_iterations = max_iterations;
  options.num_threads = 1;
  ceres::Solver::Summary solved;
  ceres::Solve(options, &problem, &solved);
  summary = {solved.initial_cost, solved.final_cost, static_cast<int>(solved.iterations.size()), solved.termination_type == ceres::CONVERGENCE};
  for (int node : used) {
    const Block& block = blocks[node];
    Similarity& pose = S_world_node[node];
    pose.rotation = Eigen::Quaterniond(block.quaternion[3], block.quaternion[0], block.quaternion[1], block.quaternion[2]).normalized();
    pose.translation = block.translation;
    pose.scale = std::exp(block.log_scale);
  }
  return summary;
}

}  // namespace hanzo::fusion::vision
