#pragma once
// Ground-vehicle trajectories (warehouse robots, cars, a person walking with a handheld
// device): a waypoint polyline driven with rounded corners and a speed profile that respects
// acceleration limits, turned into a SplineTrajectory.
//
// Geometry: every corner between two segments is replaced by a circular arc of corner_radius
// (shrunk where the segments are too short for it); a closed path also rounds the corner at its
// first waypoint, and is driven `laps` times. Heading (yaw) follows the path tangent; roll and
// pitch stay zero; z is interpolated between waypoints (ramps).
// Speed: at most max_speed, at most sqrt(max_lateral_acceleration * radius) in arcs, changing
// by at most max_acceleration (the classic forward/backward pass over arc length), starting and
// ending at rest. The vehicle stands still for still_start seconds before it moves (static
// alignment time for a filter) and still_end seconds after.
// The profile is sampled every knot_spacing seconds into B-spline control poses; the spline
// smooths it (a B-spline passes near its control poses: corners cut by millimetres at the
// default spacing).

#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"

namespace hanzo::fusion::sim {

struct GroundPathConfig {
  std::vector<Eigen::Vector3d> waypoints;  ///< world ENU, metres; >= 2 (>= 3 when closed)
  bool closed = false;                     ///< drive back to the first waypoint
  int laps = 1;                            ///< closed paths only, >= 1
  double corner_radius = 2.0;              ///< metres, > 0
  double max_speed = 1.5;                  ///< m/s, > 0
  double max_acceleration = 0.5;           ///< m/s^2, > 0
  double max_lateral_acceleration = 1.0;   ///< m/s^2, > 0
  double still_start = 3.0;                ///< seconds, >= 0
  double still_end = 1.0;                  ///< seconds, >= 0
  double knot_spacing = 0.1;               ///< seconds, > 0
};

/// Fails naming the offending field (too few waypoints, repeated waypoints, non-positive limits).
Result<SplineTrajectory> make_ground_trajectory(Timestamp start_time, const GroundPathConfig& config);

}  // namespace hanzo::fusion::sim
