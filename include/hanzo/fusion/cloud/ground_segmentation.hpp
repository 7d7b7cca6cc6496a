#pragma once
// Ground-plane segmentation by RANSAC (Fischler & Bolles 1981): planes through three random
// points, the one with the most points within `distance_threshold` wins, then it is refit by
// least squares (PCA) to its inliers. Only planes whose normal is within `max_tilt_deg` of the
// cloud frame's +z are ground, so the cloud must be in a roughly gravity-aligned frame (a
// level sensor, or a scan rotated by the IMU attitude); walls are never taken for ground.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::cloud {

struct GroundSegmentationConfig {
  double distance_threshold = 0.15;  // m from the plane to count as ground
  double max_tilt_deg = 15.0;        // largest angle between the plane normal and +z
  int max_iterations = 200;          // RANSAC hypotheses
  double min_inlier_fraction = 0.05; // of all points, for a plane to count as ground
  uint32_t seed = 1;                 // the result is deterministic for a seed
};

struct GroundSegmentation {
  bool found = false;
  std::string message;                  // why no ground plane was accepted (when !found)
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, pointing up (+z side)
  double offset = 0.0;                  // plane: normal . p + offset = 0
  std::vector<uint32_t> ground;         // indices into the cloud, ascending
  std::vector<uint32_t> obstacles;      // the other indices, ascending
};

GroundSegmentation segment_ground(const PointCloud& cloud, const GroundSegmentationConfig& config = {});

}  // namespace hanzo::fusion::cloud
