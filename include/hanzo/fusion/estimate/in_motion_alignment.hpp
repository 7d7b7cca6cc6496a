#pragma once
// In-motion (coarse) alignment of a moving ground vehicle from a short GNSS track and the IMU,
// for logs that begin with the vehicle already driving: the heading, velocity, roll and pitch a
// filter can start from, where static alignment's assumption (standing still) is false.
//
// 1. The GNSS antenna track over the last `window` seconds is fitted with a quadratic in time
//    (least squares; a line with three fixes): velocity and acceleration at the track's mean
//    time t_mid, with their standard deviations from the fit.
// 2. Heading: a ground vehicle drives along its body x axis, so its heading is the course over
//    ground (atan2 of the horizontal velocity), plus pi when it reverses (the caller knows from
//    the wheels), carried from t_mid to `now` by the gyro's yaw rate (the heading turns by the
//    integrated rate; in a corner the course at t_mid is already behind).
// 3. Velocity at `now`: the speed at t_mid plus the along-track acceleration times
//    (now - t_mid), along the course at now. The along-track acceleration is the caller's
//    measured forward acceleration (differentiated wheel speeds) when given, else the fit's when
//    it determines it to max_acceleration_sigma, else unknown (zero, with
//    unknown_acceleration as its uncertainty).
// 4. Roll and pitch with the motion compensated: the mean specific force of the last
//    `specific_force_window` seconds equals R^T (a - g); the vehicle's acceleration a is the
//    along-track acceleration (when determined) plus the centripetal acceleration of the turn
//    (gyro yaw rate times speed). Roll and pitch then solve R(roll, pitch, heading) f = a - g
//    exactly (ZYX Euler angles).
// Frames: fixes in the world frame (ENU, metres), IMU samples in the IMU's axes (mounting
// gives the body's), the result is the body's attitude and velocity in the world and the
// antenna position at `now`.
//
// Fails, naming why, with fewer than three fixes, a track shorter than min_span, a speed below
// min_speed or below min_speed_to_noise times its standard deviation (the course would be
// noise; min_speed_to_noise_full_window once the track spans the window), or no IMU sample in
// the last specific_force_window (roll and pitch unknown).
// Limits: the course is the heading only for vehicles that drive along their x axis (cars,
// wheeled robots); a sideslipping or holonomic platform gets a heading off by its slip angle,
// which the filter then has to correct (orientation_sigma includes slip_sigma for it).

#include <optional>
#include <utility>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/so3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"

namespace hanzo::fusion::estimate {

/// One GNSS fix of the antenna in the world frame.
struct GnssTrackPoint {
  Timestamp time;
  Eigen::Vector3d antenna = Eigen::Vector3d::Zero();  ///< world (ENU), m
  double horizontal_sigma = 1.0;                      ///< m, 1-sigma per horizontal axis
};

struct InMotionAlignmentConfig {
  double window = 4.0;                   ///< s: the fixes used are the ones this far before the newest
  double min_span = 1.0;                 ///< s: first to last fix used
  double min_speed = 2.0;                ///< m/s: slower, the course is not a heading
  /// Speed / its sigma: the course to 1/20 rad, or to 1/5 rad once the window is full (a slow
  /// vehicle or noisy fixes should not wait for ever).
  double min_speed_to_noise = 20.0;
  double min_speed_to_noise_full_window = 5.0;
  double max_acceleration_sigma = 0.5;   ///< m/s^2: a fitted acceleration noisier than this is not used
  double unknown_acceleration = 1.5;     ///< m/s^2: the 1-sigma of an acceleration the fit cannot give
  double slip_sigma = 0.05;              ///< rad: course minus heading of a real vehicle (slip, mounting)
  double specific_force_window = 0.5;    ///< s of IMU samples averaged for roll and pitch
};

struct InMotionAlignment {
  SO3 R_world_body;
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();         ///< body velocity in the world at `now`, m/s
  Eigen::Vector3d antenna = Eigen::Vector3d::Zero();          ///< the fit's antenna position at `now`, world
  Eigen::Vector3d orientation_sigma = Eigen::Vector3d::Zero();  ///< roll, pitch, yaw 1-sigma, rad
  double velocity_sigma = 0.0;                                ///< m/s per axis
  double speed = 0.0;                                         ///< horizontal speed at t_mid, m/s
};

/// What the caller measured besides GNSS and IMU.
struct InMotionAlignmentInput {
  std::vector<GnssTrackPoint> fixes;  ///< time order
  std::vector<ImuSample> imu;         ///< recent samples in time order (they cover the fixes' mean time to now)
  ImuMounting mounting;
  Timestamp now;                      ///< the time the alignment is for (the newest fix)
  double gravity_magnitude = kStandardGravity;
  bool reversing = false;             ///< the vehicle drives backwards (wheels)
  /// Forward acceleration (m/s^2) and its 1-sigma over the last second, e.g. from wheel speeds.
  std::optional<std::pair<double, double>> forward_acceleration;
};

/// See the header comment.
Result<InMotionAlignment> align_in_motion(const InMotionAlignmentInput& input, const InMotionAlignmentConfig& config = {});

/// Roll and pitch of R = Rz(yaw) Ry(pitch) Rx(roll) with R f_body = f_world for the given yaw
/// (exact when |f_body| = |f_world|; otherwise the closest in direction).
Eigen::Vector2d roll_pitch_from_specific_force(const Eigen::Vector3d& f_body, const Eigen::Vector3d& f_world, double yaw);

}  // namespace hanzo::fusion::estimate
