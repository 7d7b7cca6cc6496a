#pragma once
// Sparse scene points from posed views, where 3D Gaussian splatting starts its Gaussians (Kerbl
// et al. 2023, Sec. 5.1, start from the SfM points of COLMAP; here the poses are given, so only
// the points are made): ORB features (OpenCV) of each view matched against those of its nearest
// views (camera centres, at most max_angle_degrees between the optical axes), Lowe's ratio test,
// mutual best matches; each match triangulated linearly (DLT, Hartley and Zisserman, Sec. 12.2)
// with the known cameras and kept when it lies in front of both, the rays part by at least
// min_parallax_degrees and it reprojects within max_reprojection_px in both views. Views with
// masks (RGBA) only match features on their foreground.
//
// Frames: world (the views' frame); units as the views' poses. Deterministic. Fails never:
// views without texture or overlap give no points (the caller falls back to another start).

#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/neural/view_dataset.hpp"

namespace hanzo::fusion::neural {

struct ViewPointsConfig {
  int features_per_view = 2000;
  int neighbours = 4;                  ///< views each view is matched with (nearest centres)
  double max_angle_degrees = 60.0;     ///< between the two optical axes
  double ratio = 0.8;                  ///< Lowe's ratio test
  double min_parallax_degrees = 1.0;
  double max_reprojection_px = 2.0;
};

std::vector<Eigen::Vector3f> triangulate_view_points(const std::vector<PosedView>& views, const ViewPointsConfig& config = {});

}  // namespace hanzo::fusion::neural
