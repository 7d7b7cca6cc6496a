#include "hanzo/fusion/sim/planar_odometry_error.hpp"

namespace hanzo::fusion::sim {

std::vector<SE2> corrupt_planar_odometry(const std::vector<SE2>& true_poses, const PlanarOdometryError& error) {
  std::vector<SE2> odometry;
  odometry.reserve(true_poses.size());
  for (size_t i = 0; i < true_poses.size(); ++i) {
    if (i == 0) {
      odometry.push_back(true_poses[0]);
      continue;
    }
    const SE2 step = true_poses[i - 1].inverse() * true_poses[i];
    const double distance = step.translation().norm();
    const SE2 corrupted(step.angle() + error.heading_drift_per_meter * distance, (1.0 + error.scale_error) * step.translation());
    odometry.push_back(odometry.back() * corrupted);
  }
  return odometry;
}

}  // namespace hanzo::fusion::sim
