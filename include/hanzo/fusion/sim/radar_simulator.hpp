#pragma once
// RadarSimulator: an automotive-style FMCW radar's target list (range, azimuth, elevation,
// Doppler radial velocity, RCS) by ray casting the World.
//
// Each scan casts a grid of rays over the field of view (azimuth_resolution x elevation rows)
// from the radar pose at the scan time. Hits are grouped per object and per azimuth cell of
// cluster_azimuth radians; each group becomes one target at its nearest hit, so a long wall
// gives a row of targets and a pole gives one. The ground is not a target (real radars
// suppress it). Per target, in the radar frame (x forward, azimuth counter-clockwise from x,
// elevation up from the x-y plane):
//   radial_velocity = (v_object - v_radar) . unit line of sight   (positive: moving away)
//   plus N(0, sigma^2) noise on range, azimuth, elevation, radial velocity and RCS, where
//   RCS = the object's material radar_cross_section.
// clutter_rate false alarms per scan (Poisson) appear uniformly in the field of view with
// random range, Doppler uniform in +-10 m/s and low RCS (-10 dBsm): a robust ego-velocity
// estimator must reject them together with the moving objects.

#include <cstdint>
#include <random>
#include <string>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"
#include "hanzo/fusion/sim/world.hpp"

namespace hanzo::fusion::sim {

struct RadarSimulatorConfig {
  double rate_hz = 20.0;
  double horizontal_fov = 2.0944;      ///< radians (120 deg), centred on x
  double vertical_fov = 0.2618;        ///< radians (15 deg)
  double azimuth_resolution = 0.0175;  ///< radians between rays (1 deg)
  int elevation_rows = 5;
  double cluster_azimuth = 0.0524;     ///< radians (3 deg)
  double max_range = 100.0;            ///< metres
  double range_noise = 0.1;            ///< metres
  double azimuth_noise = 0.0087;       ///< radians (0.5 deg)
  double elevation_noise = 0.0175;     ///< radians (1 deg)
  double velocity_noise = 0.05;        ///< m/s
  double rcs_noise = 1.0;              ///< dB
  double clutter_rate = 2.0;           ///< false targets per scan
  SE3 T_body_radar;
  std::string frame_id = "radar";
  uint64_t seed = 5;
};

class RadarSimulator {
 public:
  /// world and trajectory must outlive the simulator.
  RadarSimulator(RadarSimulatorConfig config, const World& world, const SplineTrajectory& trajectory);

  /// The scan at `time`; call in increasing time order. May hold no targets.
  msgs::RadarMessage measure(Timestamp time);

 private:
  RadarSimulatorConfig config_;
  const World& world_;
  const SplineTrajectory& trajectory_;
  std::mt19937_64 random_;
};

}  // namespace hanzo::fusion::sim
