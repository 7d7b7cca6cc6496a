#pragma once
// Loop-closure geometry of the visual odometry (internal to the vision module):
//  - Similarity: a 3D similarity transform p -> scale R p + t (Sim3; scale 1 is an SE3);
//  - optimize_similarity_pose_graph: the pose graph of keyframe similarities after a loop
//    closure (ORB-SLAM's essential-graph optimization, Strasdat et al. 2010 "Scale Drift-Aware
//    Large Scale Monocular SLAM"), Levenberg-Marquardt on Ceres.
//
// Frames: S_world_node maps a keyframe's camera frame into the world; an edge's S_from_to maps
// `to`'s camera frame into `from`'s. Edge residual (7): 2 vec(q_measured^-1 q_estimated),
// t_estimated - t_measured (in `from`'s units), ln s_estimated - ln s_measured, where
// estimated = S_world_from^-1 S_world_to; weighted by the edge's weight (identity otherwise).

#include <map>
#include <set>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "hanzo/fusion/core/se3.hpp"

namespace hanzo::fusion::vision {

struct Similarity {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double scale = 1.0;

  static Similarity from(const SE3& pose) { return {pose.rotation().quaternion(), pose.translation(), 1.0}; }
  /// The rigid part (rotation, translation); the scale is dropped.
  SE3 rigid() const { return SE3(SO3(rotation.normalized()), translation); }
  Eigen::Vector3d operator*(const Eigen::Vector3d& point) const { return scale * (rotation * point) + translation; }
  Similarity operator*(const Similarity& other) const {
    return {rotation * other.rotation, scale * (rotation * other.translation) + translation, scale * other.scale};
  }
  Similarity inverse() const {
    const Eigen::Quaterniond inverse_rotation = rotation.conjugate();
    return {inverse_rotation, -(inverse_rotation * translation) / scale, 1.0 / scale};
  }
};

struct SimilarityEdge {
  int from = 0;
  int to = 0;
  Similarity S_from_to;
  double weight = 1.0;  ///< scales the residual
};

struct SimilarityPoseGraphSummary {
  double initial_cost = 0.0;
  double final_cost = 0.0;
  int iterations = 0;
  bool converged = false;
};

/// Optimizes the poses of every node an edge touches, except those in `fixed` (at least one
/// must be fixed: the gauge); with fix_scale (stereo, metric maps) scales stay as they are.
SimilarityPoseGraphSummary optimize_similarity_pose_graph(std::map<int, Similarity>& S_world_node, const std::vector<SimilarityEdge>& edges,
                                                          const std::set<int>& fixed, bool fix_scale, int max_iterations);

}  // namespace hanzo::fusion::vision
