#pragma once
// Stations: a rig carried from one pose to the next and held still at each, as a sensor rig is
// set up for target-based calibration (on a tripod, or held against a board at several angles).
//
// The body stands at stations[0] for `hold` seconds, moves to stations[1] over `move` seconds
// (position and orientation eased by smoothstep, so it starts and stops at rest), holds, and so on;
// the trajectory lasts N hold + (N - 1) move seconds. Orientation of a station:
// R_world_body = R_z(yaw) R_y(pitch) R_x(roll). The result is a SplineTrajectory whose control
// poses repeat the station's pose while it holds: with hold >= 4 knot_spacing the body is exactly
// still for hold - 3 knot_spacing seconds of each hold (a cubic B-spline segment is the pose
// when its 4 control poses are).

#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"

namespace hanzo::fusion::sim {

struct StationPose {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();        ///< world, m
  Eigen::Vector3d roll_pitch_yaw = Eigen::Vector3d::Zero();  ///< radians
};

struct StationsTrajectoryConfig {
  std::vector<StationPose> stations;  ///< at least 1
  double hold = 2.0;                  ///< s at each station, >= 4 knot_spacing
  double move = 2.0;                  ///< s between stations, > 0
  double knot_spacing = 0.05;         ///< s, > 0
};

/// Fails naming the field: no stations, a non-finite station, hold shorter than 4 knot spacings,
/// move or knot_spacing not positive.
Result<SplineTrajectory> make_stations_trajectory(Timestamp start_time, const StationsTrajectoryConfig& config);

}  // namespace hanzo::fusion::sim
