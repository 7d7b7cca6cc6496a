#pragma once
// A point seen from several camera poses, triangulated: the MSCKF's features (msckf.hpp) and the
// landmarks of the Session's visual-inertial keyframe graph.
//
// Frames: each view is a camera at T_world_body * T_body_camera seeing the point at undistorted
// normalized coordinates (x/z, y/z) in its own frame; the point is in the world frame, metres.

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/se3.hpp"

namespace hanzo::fusion::vision {

/// One observation of a feature with the poses it was taken from.
struct FeatureView {
  SE3 T_world_body;
  SE3 T_body_camera;
  Eigen::Vector2d normalized = Eigen::Vector2d::Zero();
};

struct FeatureTriangulationConfig {
  double min_depth = 0.1;   ///< metres, in every view
  double max_depth = 60.0;  ///< metres, in every view
  int iterations = 8;       ///< Gauss-Newton iterations after the linear solution
  double min_parallax_rad = 0.0;  ///< the widest angle between two viewing rays must reach this
};

/// The world point that best explains the views (at least two, from at least two camera
/// positions): the linear solution of [b]x (R_camera_world p_f + t_camera_world) = 0 over every
/// view, refined by Gauss-Newton on the normalized reprojection errors. nullopt when the views
/// are degenerate (too little parallax: the 3 x 3 normal matrix is near singular, or the widest
/// angle between two viewing rays is under min_parallax_rad) or a depth is outside
/// [min_depth, max_depth].
std::optional<Eigen::Vector3d> triangulate_feature(const std::vector<FeatureView>& views, const FeatureTriangulationConfig& config);

}  // namespace hanzo::fusion::vision
