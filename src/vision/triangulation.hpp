#pragma once
// Two-view triangulation of a point from undistorted normalized coordinates (x/z, y/z) in two
// cameras with known poses: the linear (DLT) solution, the null vector of
//   [x1 P1_3 - P1_1; y1 P1_3 - P1_2; x2 P2_3 - P2_1; y2 P2_3 - P2_2],  P = [R | t] (T_camera_world)
// (Hartley and Zisserman, 12.2), and the checks a new landmark must pass.

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/se3.hpp"

namespace hanzo::fusion::vision {

/// The world point, or nullopt when the system is degenerate (point at infinity).
std::optional<Eigen::Vector3d> triangulate(const SE3& T_camera1_world, const Eigen::Vector2d& normalized1, const SE3& T_camera2_world,
                                           const Eigen::Vector2d& normalized2);

/// The same over any number of views (at least two): 2 rows per view, the null vector by SVD.
std::optional<Eigen::Vector3d> triangulate_views(const std::vector<SE3>& T_camera_world, const std::vector<Eigen::Vector2d>& normalized);

/// The angle (radians) between the two viewing rays of a world point.
double triangulation_angle(const SE3& T_camera1_world, const SE3& T_camera2_world, const Eigen::Vector3d& point_world);

}  // namespace hanzo::fusion::vision
