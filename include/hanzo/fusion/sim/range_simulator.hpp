#pragma once
// RangeSimulator: a single-beam rangefinder (ultrasonic or infrared) looking along its +x axis.
// The reading is the nearest surface any of the cone's rays hits (an ultrasonic sensor reports
// its first echo): the axis and two rings of 8 rays at a quarter and half of field_of_view
// from it; plus Gaussian noise. Nothing within max_range reads +inf, nearer than min_range -inf
// (REP 117, as msgs::RangeMessage).

#include <cstdint>
#include <random>
#include <string>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"
#include "hanzo/fusion/sim/world.hpp"

namespace hanzo::fusion::sim {

struct RangeSimulatorConfig {
  double rate_hz = 20.0;
  double field_of_view = 0.26;  ///< radians, full cone angle (15 deg, a common ultrasonic module)
  double min_range = 0.02;      ///< metres
  double max_range = 4.0;       ///< metres
  double range_noise = 0.01;    ///< metres, standard deviation
  msgs::RangeRadiation radiation = msgs::RangeRadiation::kUltrasound;
  SE3 T_body_range;
  std::string frame_id = "range";
  uint64_t seed = 6;
};

class RangeSimulator {
 public:
  /// world and trajectory must outlive the simulator.
  RangeSimulator(RangeSimulatorConfig config, const World& world, const SplineTrajectory& trajectory);

  /// The reading at `time`; call in increasing time order.
  msgs::RangeMessage measure(Timestamp time);

 private:
  RangeSimulatorConfig config_;
  const World& world_;
  const SplineTrajectory& trajectory_;
  std::mt19937_64 random_;
};

}  // namespace hanzo::fusion::sim
