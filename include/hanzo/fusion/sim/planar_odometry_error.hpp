#pragma once
// Odometry with the systematic errors of a badly calibrated wheeled robot, made from true
// planar poses (to test scan matching and loop closure on logs whose odometry is already
// corrected, such as the "corrected" CARMEN logs).

#include <cmath>
#include <vector>

#include "hanzo/fusion/core/se2.hpp"

namespace hanzo::fusion::sim {

struct PlanarOdometryError {
  double scale_error = 0.05;                            ///< each step's distance x (1 + scale_error)
  double heading_drift_per_meter = 2.0 * M_PI / 180.0;  ///< rad added to the heading per metre driven
};

/// Odometry poses for `true_poses` (same count, the first pose kept): each step T_i^-1 T_{i+1}
/// keeps its direction of travel and heading change, its translation is scaled and its heading
/// change grows by heading_drift_per_meter x its length.
std::vector<SE2> corrupt_planar_odometry(const std::vector<SE2>& true_poses, const PlanarOdometryError& error);

}  // namespace hanzo::fusion::sim
