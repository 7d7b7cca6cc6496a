#pragma once
// SplineTrajectory: a smooth body trajectory T_world_body(t) for the simulator, a uniform
// cumulative cubic B-spline on SO3 x R3 (Lovegrove et al. 2013, "Spline Fusion", eq. 4-6;
// derivatives as Sommer et al. 2020, "Efficient Derivative Computation for Cumulative
// B-Splines on Lie Groups", sec. 4). Position and orientation are twice continuously
// differentiable, so the IMU truth (acceleration, angular velocity) derived from it is
// continuous and integrates back to the trajectory.
//
// Frames and units: world ENU, body FLU; seconds, metres, radians. With control poses
// T_0..T_{N-1} spaced `knot_spacing` apart from `start_time`, the trajectory is defined on
// [start_time, start_time + (N - 3) * knot_spacing]; segment i uses T_i..T_{i+3}. A B-spline
// passes near, not through, its control poses.

#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"

namespace hanzo::fusion::sim {

/// The trajectory's state at one time.
struct TrajectorySample {
  SE3 T_world_body;
  Eigen::Vector3d velocity_world = Eigen::Vector3d::Zero();          ///< m/s
  Eigen::Vector3d acceleration_world = Eigen::Vector3d::Zero();      ///< m/s^2 (kinematic, no gravity)
  Eigen::Vector3d angular_velocity_body = Eigen::Vector3d::Zero();   ///< rad/s, body frame
};

class SplineTrajectory {
 public:
  /// Fails with fewer than 4 control poses or a non-positive knot spacing.
  static Result<SplineTrajectory> create(Timestamp start_time, Duration knot_spacing, std::vector<SE3> control_poses);

  Timestamp start_time() const { return start_; }
  Timestamp end_time() const;
  /// The state at `time`; times outside [start_time, end_time] are clamped to it.
  TrajectorySample sample(Timestamp time) const;

 private:
  SplineTrajectory(Timestamp start, double spacing_seconds, std::vector<SE3> control_poses)
      : start_(start), spacing_(spacing_seconds), control_(std::move(control_poses)) {}
  Timestamp start_;
  double spacing_;  // seconds
  std::vector<SE3> control_;
};

}  // namespace hanzo::fusion::sim
