#pragma once
// WheelSlipMonitor: tells when wheel odometry disagrees with the LiDAR odometry's own motion
// (the Session stops fusing the wheels then: a slipping or spinning wheel drags the filter,
// which then gates the LiDAR poses and diverges).
//
// Inputs: the wheels' cumulative forward distance (mean of left and right, m) at their times,
// and the LiDAR odometry's motion between registered sweeps expressed as the forward (x)
// displacement of the wheel frame (m, signed). Over the sweeps of the last window_s the LiDAR's
// forward distance is compared with the wheels' over the same span:
//   |d_wheels - d_lidar| > absolute_tolerance_m + relative_tolerance * |d_lidar|  -> slipping
// and the wheels are trusted again once no window has disagreed for recovery_s. Windows with a
// degenerate or weather-degraded sweep (the LiDAR's distance along a corridor is not known), or
// not covered by wheel data, are not judged. Times are the body clock; units m and s.

#include <cstdint>
#include <deque>

#include "hanzo/fusion/core/time.hpp"

namespace hanzo::fusion::pipeline {

struct WheelSlipConfig {
  double window_s = 0.5;              ///< LiDAR motion compared over this span
  double absolute_tolerance_m = 0.03; ///< registration and wheel quantization noise over a window
  double relative_tolerance = 0.05;   ///< scale errors of calibrated wheels stay well below 5 %
  double recovery_s = 1.0;            ///< agreement this long before the wheels are fused again
};

class WheelSlipMonitor {
 public:
  explicit WheelSlipMonitor(WheelSlipConfig config = {}) : config_(config) {}

  /// A wheel message: cumulative forward distance (m) at `time` (in time order).
  void add_wheels(Timestamp time, double distance);
  /// The LiDAR's forward displacement in the wheel frame between two registered sweeps (in time
  /// order); `reliable` false for degenerate or weather-degraded sweeps.
  void add_lidar_motion(Timestamp from, Timestamp to, double forward, bool reliable);

  bool slipping() const { return slipping_; }
  uint64_t episodes() const { return episodes_; }  ///< times slipping started
  /// The last window judged: wheel minus LiDAR distance (m).
  double last_difference() const { return last_difference_; }

 private:
  /// Compares the newest LiDAR window with the wheels once they cover it.
  void judge();
  /// The wheels' distance at `time`, interpolated; false outside their history.
  bool wheel_distance_at(Timestamp time, double& distance) const;

  struct WheelSample {
    Timestamp time;
    double distance = 0.0;
  };
  struct LidarMotion {
    Timestamp from, to;
    double forward = 0.0;
    bool reliable = true;
  };
  WheelSlipConfig config_;
  std::deque<WheelSample> wheels_;
  std::deque<LidarMotion> motions_;
  bool slipping_ = false;
  Timestamp last_disagreement_;
  Timestamp judged_until_;  ///< the end of the last window judged
  uint64_t episodes_ = 0;
  double last_difference_ = 0.0;
};

}  // namespace hanzo::fusion::pipeline
