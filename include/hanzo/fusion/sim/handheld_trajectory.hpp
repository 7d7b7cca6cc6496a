#pragma once
// Handheld AR device: a person walking a waypoint path (GroundPathConfig at walking pace)
// while the device bobs with the steps and the person looks around.
//
// T_world_device(t) = T_world_walk(t) * (R_z(yaw(t)) R_y(pitch(t)), (0, 0, bob(t))), where
//   bob(t)   = s(t) * bob_amplitude * sin(2 pi step_frequency t)        (s = speed / max_speed)
//   yaw(t)   = look_yaw_amplitude * sin(2 pi t / look_period)
//   pitch(t) = look_pitch_amplitude * sin(2 pi t / (0.7 look_period))
// and the walk's z is the device height (e.g. 1.4 m). yaw and pitch are scaled by a ramp that is
// 0 while the walk stands still (still_start, still_end: the person holds the device still for
// a filter's static alignment) and rises to 1 over the first second after (smoothstep). The result is a SplineTrajectory with
// the walk's knot spacing.

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/sim/ground_path.hpp"

namespace hanzo::fusion::sim {

struct HandheldTrajectoryConfig {
  GroundPathConfig walk;               ///< set max_speed to a walking pace (~1.2 m/s)
  double bob_amplitude = 0.03;         ///< metres
  double step_frequency = 1.8;         ///< Hz
  double look_yaw_amplitude = 0.5;     ///< radians
  double look_pitch_amplitude = 0.2;   ///< radians
  double look_period = 7.0;            ///< seconds, > 0
};

Result<SplineTrajectory> make_handheld_trajectory(Timestamp start_time, const HandheldTrajectoryConfig& config);

}  // namespace hanzo::fusion::sim
