#pragma once
// Matching by projection (ORB-SLAM's SearchByProjection): landmarks with known world positions
// are projected into an image at a predicted pose and each is matched to the keypoint nearest in
// descriptor among those near its projection. Used by tracking against the local map and by
// relocalization in a saved map (a first PnP pose, then every map landmark it brings into view).

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/vision/orb_extractor.hpp"

namespace hanzo::fusion::vision {

// Keypoint indices in square cells of `cell` pixels, for neighbourhood searches.
class KeypointGrid {
 public:
  KeypointGrid(const std::vector<cv::KeyPoint>& keypoints, cv::Size image_size, int cell)
      : cell_(cell), columns_(image_size.width / cell + 1), rows_(image_size.height / cell + 1), cells_(static_cast<std::size_t>(columns_ * rows_)) {
    for (std::size_t k = 0; k < keypoints.size(); ++k) {
      cells_[static_cast<std::size_t>(row_of(keypoints[k].pt.y) * columns_ + column_of(keypoints[k].pt.x))].push_back(static_cast<int>(k));
    }
  }
  /// Calls visit(k) for every keypoint in the cells that overlap the square of half-side
  /// `radius` around (u, v) (a superset of the keypoints within `radius`).
  template <typename Visit>
  void for_each_near(double u, double v, double radius, Visit&& visit) const {
    for (int r = row_of(v - radius); r <= row_of(v + radius); ++r) {
      for (int c = column_of(u - radius); c <= column_of(u + radius); ++c) {
        for (int k : cells_[static_cast<std::size_t>(r * columns_ + c)]) visit(k);
      }
    }
  }

 private:
  int column_of(double u) const { return std::clamp(static_cast<int>(std::floor(u / cell_)), 0, columns_ - 1); }
  int row_of(double v) const { return std::clamp(static_cast<int>(std::floor(v / cell_)), 0, rows_ - 1); }

  int cell_, columns_, rows_;
  std::vector<std::vector<int>> cells_;
};

/// A landmark to look for in the image.
struct ProjectedLandmark {
  Eigen::Vector3d position_world;
  cv::Mat descriptor;                         ///< one row: CV_8UC1 (ORB) or CV_32FC1 (learned), as the keypoints'
  int octave = -1;                            ///< the pyramid level it was seen at; -1: unknown (any level)
  int id = 0;                                 ///< returned in the matches
};

struct ProjectionSearch {
  double radius_px = 15.0;          ///< search radius around the projection at octave 0
  double scale_factor = 1.2;        ///< the radius grows by this per octave of the landmark (or the keypoint, when unknown)
  double ratio = 0.9;               ///< best against second-best descriptor distance
  int max_descriptor_distance = 64;  ///< descriptor_distance()'s units (Hamming bits for ORB)
  int max_octave_difference = 2;    ///< keypoints further from the landmark's octave are skipped
};

/// (keypoint, landmark id) pairs: each landmark that projects inside the image (at T_camera_world)
/// takes the keypoint nearest in descriptor within the search radius, when it passes the ratio and
/// distance tests; a keypoint claimed by several landmarks goes to the one it matches best.
std::vector<std::pair<int, int>> match_by_projection(const std::vector<ProjectedLandmark>& landmarks, const ImageFeatures& features,
                                                     const KeypointGrid& grid, const PinholeCamera& camera, const SE3& T_camera_world,
                                                     const ProjectionSearch& search);

}  // namespace hanzo::fusion::vision
