#pragma once
// WheelOdometrySimulator: cumulative left/right wheel distances of a differential-drive base.
//
// The axle centre sits at T_body_wheels on the body (its x axis forward, z up). Between two
// measurements the true wheel travel is integrated in 1 ms steps (midpoint rule) from the axle's
// forward speed v and yaw rate w:  left += (v - w b / 2) dt,  right += (v + w b / 2) dt,
// b = wheel_separation. Sideways and vertical motion is invisible to wheels.
//
// Reported increments = true increment * scale_error (systematic: a wrong wheel radius)
// * (1 + N(0, distance_noise^2)), and inside a slip episode also * left_scale / right_scale
// (a wheel spinning on a wet floor reports more than it travels: scale > 1; a locked,
// sliding wheel less: scale < 1). Distances start at 0 at the first measurement.

#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"

namespace hanzo::fusion::sim {

struct WheelSlipEpisode {
  Timestamp start;
  Timestamp end;
  double left_scale = 1.3;   ///< reported / true distance of the left wheel
  double right_scale = 1.0;
};

struct WheelOdometrySimulatorConfig {
  double rate_hz = 50.0;
  double wheel_separation = 0.5;  ///< metres, > 0
  double wheel_radius = 0.1;      ///< metres (reported in the message)
  SE3 T_body_wheels;              ///< axle centre
  double distance_noise = 0.01;   ///< relative standard deviation of each increment
  Eigen::Vector2d scale_error{1.0, 1.0};  ///< left, right systematic scale
  std::vector<WheelSlipEpisode> slips;
  std::string frame_id = "wheels";
  uint64_t seed = 4;
};

class WheelOdometrySimulator {
 public:
  WheelOdometrySimulator(WheelOdometrySimulatorConfig config, const SplineTrajectory& trajectory);

  /// The cumulative distances at `time`; call in increasing time order.
  msgs::WheelOdometryMessage measure(Timestamp time);
  /// Forward speed (m/s) and yaw rate (rad/s) of the axle at `time`, noiseless.
  Eigen::Vector2d axle_speed_and_yaw_rate(Timestamp time) const;

 private:
  const WheelSlipEpisode* slip_at(Timestamp time) const;

  WheelOdometrySimulatorConfig config_;
  const SplineTrajectory* trajectory_;
  std::mt19937_64 random_;
  std::optional<Timestamp> previous_time_;
  double left_ = 0.0;
  double right_ = 0.0;
};

}  // namespace hanzo::fusion::sim
