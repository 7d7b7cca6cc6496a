#pragma once
// Static alignment: the initial attitude and gyro bias from IMU samples recorded while the body
// stands still. The mean specific force points up (it opposes gravity), which fixes roll and
// pitch; the mean angular rate is the gyro bias (the Earth's rotation, 7.3e-5 rad/s, is left
// in it). Heading is not observable from a still IMU: the caller supplies it (0, an IMU
// heading, or a GNSS course later).
//
// Fails with a message when there are fewer than min_samples samples or when the samples show
// motion: the standard deviation of the specific force or of the rate, over means of
// motion_window_s windows, above the thresholds. The window means let a platform that vibrates
// while standing (a MAV with its rotors running: EuRoC V1_01's first seconds have a specific
// force std of 0.8 m/s^2 sample to sample, 0.11 m/s^2 over 50 ms means) align statically, while
// a push or a turn still shows. Spans under three windows use the samples themselves.

#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"

namespace hanzo::fusion::estimate {

struct StaticAlignmentConfig {
  int min_samples = 10;
  double max_accel_std = 0.3;  // m/s^2, std of each axis of the specific force while still
  double max_gyro_std = 0.05;  // rad/s, std of each axis of the rate while still
  double motion_window_s = 0.05;  // s, the windows whose means the stds are taken over
};

struct StaticAlignment {
  SO3 R_world_body;                                      // roll and pitch from gravity, the given yaw
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();   // rad/s, IMU axes
  double gravity_magnitude = kStandardGravity;           // |mean specific force|, m/s^2
  int samples = 0;
};

Result<StaticAlignment> align_static(const std::vector<ImuSample>& samples, const ImuMounting& mounting, double yaw,
                                     const StaticAlignmentConfig& config = {});

/// The rotation with the given roll, pitch, yaw (ZYX: Rz(yaw) Ry(pitch) Rx(roll)).
SO3 rotation_from_roll_pitch_yaw(double roll, double pitch, double yaw);

}  // namespace hanzo::fusion::estimate
