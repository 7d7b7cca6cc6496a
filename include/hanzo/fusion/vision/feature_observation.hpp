#pragma once
// FeatureObservation: one feature seen in one camera image, the unit the feature tracker
// (feature_tracker.hpp) produces and the MSCKF (msckf.hpp) consumes.

#include <cstdint>

#include <Eigen/Core>

namespace hanzo::fusion::vision {

/// The track id is the same in every frame and camera that sees the same point; coordinates are
/// UNDISTORTED normalized (x/z, y/z) in the camera's frame (x right, y down, z forward).
struct FeatureObservation {
  uint64_t feature_id = 0;
  int camera = 0;  ///< 0: the left (or only) camera, 1: the right camera of a stereo rig
  Eigen::Vector2d normalized = Eigen::Vector2d::Zero();
};

}  // namespace hanzo::fusion::vision
