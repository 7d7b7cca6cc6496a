#pragma once
// Aggressive 6-DOF drone flight: a 3D Lissajous figure (a figure eight that also climbs and
// sinks) flown by a quadrotor, turned into a SplineTrajectory.
//
//   p(t) = center + e(t) * (size_x sin(w t), size_y sin(2 w t) / 2, size_z sin(3 w t)),  w = 2 pi / period
//
// e(t) ramps smoothly (quintic smoothstep) from 0 to 1 over ramp_time after still_start
// seconds of hover, so the drone leaves the hover without a jump in velocity or
// acceleration. Attitude as a quadrotor's: the body z axis is along the thrust, a(t) + g z,
// so the drone rolls and pitches into every turn; yaw swings +-yaw_amplitude with yaw_period.
// Control poses every knot_spacing seconds (default 50 ms for the fast motion).

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"

namespace hanzo::fusion::sim {

struct DroneTrajectoryConfig {
  Eigen::Vector3d center{0.0, 0.0, 2.0};  ///< world ENU, metres
  Eigen::Vector3d size{4.0, 3.0, 0.8};    ///< amplitudes, metres (>= 0)
  double period = 12.0;                   ///< seconds per figure, > 0
  double duration = 60.0;                 ///< seconds of flight after the hover, > 0
  double still_start = 2.0;               ///< seconds of hover, >= 0
  double ramp_time = 4.0;                 ///< seconds, > 0
  double yaw_amplitude = 0.8;             ///< radians
  double yaw_period = 9.0;                ///< seconds, > 0
  double gravity = 9.81;
  double knot_spacing = 0.05;             ///< seconds, > 0
};

Result<SplineTrajectory> make_drone_trajectory(Timestamp start_time, const DroneTrajectoryConfig& config);

}  // namespace hanzo::fusion::sim
