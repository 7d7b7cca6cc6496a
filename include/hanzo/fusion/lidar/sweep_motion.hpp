#pragma once
// SweepMotion: how a spinning LiDAR moved during one sweep, for deskewing (moving every point
// from the sensor frame at its own time into the sensor frame at one reference time).
//
// The motion is T_reference_sensor(t): the sensor's pose at time t (seconds after the scan
// time, the clock of the per-point times) in the sensor frame at the reference time. Two
// kinds:
//  - constant_twist: T_reference_sensor(t) = exp((t - reference_time) * twist), the
//    constant-velocity model of KISS-ICP (no IMU);
//  - from_samples: poses sampled during the sweep, e.g. from an IMU-propagated filter every
//    IMU period (FAST-LIO's backward propagation uses the IMU the same way); between two
//    samples the motion is the geodesic (constant twist over the segment), before the first and
//    after the last sample the end segment's twist is extrapolated. Accelerations and turns
//    that change during the sweep are then followed to the sampling period.
// Units: seconds, metres, radians; twists are (rho, phi) per second in the moving frame
// (right perturbation, as SE3::exp).

#include <vector>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"

namespace hanzo::fusion::lidar {

class SweepMotion {
 public:
  /// No motion (deskewing changes nothing).
  SweepMotion() = default;
  /// Constant body twist (rho, phi per second) about `reference_time`.
  static SweepMotion constant_twist(const SE3::Tangent& twist_per_second, double reference_time);
  /// Poses T_reference_sensor at strictly increasing `times` (at least two; finite). Errors name
  /// the first bad sample (sizes differ, fewer than two, time not after the previous one, NaN).
  static Result<SweepMotion> from_samples(std::vector<double> times, const std::vector<SE3>& T_reference_sensor);

  /// T_reference_sensor at time t (s after the scan time).
  SE3 at(double time) const;
  /// True when deskewing with this motion changes nothing (no motion).
  bool is_identity() const;
  /// Number of segments (0 for a constant twist or no motion).
  std::size_t segments() const { return times_.empty() ? 0 : times_.size() - 1; }

 private:
  // Samples: T_reference_sensor at times_[i] and the twist per second to the next sample (the
  // last segment's twist repeated for the last sample). A constant twist is one sample at the
  // reference time with identity pose.
  std::vector<double> times_;
  std::vector<SE3> poses_;
  std::vector<SE3::Tangent> twists_;
};

/// Moves every point of `scan` (sensor frame at its own time, `scan.times`) into the sensor frame
/// at the motion's reference time: p_reference = T_reference_sensor(t) p. Scans without
/// per-point times are left as they are. Consecutive points with the same time (a firing
/// column) share one transform. Points are split over up to num_threads threads.
void deskew(cloud::PointCloud& scan, const SweepMotion& motion, int num_threads = 1);

}  // namespace hanzo::fusion::lidar
