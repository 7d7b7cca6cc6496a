#pragma once
// Extrinsic and temporal calibration of a sensor from motion: hand-eye calibration during
// robot motion (spec "Calibration"). The body and the sensor are rigidly attached and each
// sees its own motion: the body through its IMU's gyroscope or a body trajectory (GNSS/INS,
// motion capture, a calibrated rig), the sensor through its own metric odometry (LiDAR
// odometry of the sensor alone, stereo visual odometry, poses of a calibration target). The
// procedure finds T_body_sensor and the time offset between the clocks, in the calibration
// file's convention t_body = t_sensor + time_offset.
//
// Method (calibrate_from_motion):
//  1. Pairs: consecutive sensor poses at least `pair_interval` apart give the sensor's
//     relative motions B_k (sensor clock); the body's motion A_k over the same interval in
//     body time comes from the body poses (interpolated) or the gyroscope (integrated). For a
//     rigid mount A_k = X B_k X^-1 with X = T_body_sensor: the hand-eye equation A X = X B
//     (Tsai & Lenz 1989).
//  2. Time offset: the rotation angle of A_k equals that of B_k whatever X is. The offset that
//     minimizes sum_k (|log R_A_k| - |log R_B_k|)^2 is found by a scan of
//     [-max_time_offset, max_time_offset] every `time_offset_step` (the correlation of rotation
//     rates of the spec's temporal calibration), refined by golden-section search on the full
//     residual of step 3 once R_X is known.
//  3. Rotation: log R_A_k = R_X log R_B_k for every pair; R_X maximizes sum a_k^T R b_k
//     (Park & Martin 1994; solved by SVD as in Kabsch's algorithm) over pairs turning at least
//     `min_pair_rotation`. With a gyroscope its constant bias b_g adds b_g dt_k to log R_A_k;
//     R_X and b_g are alternated (the gyroscope is re-integrated with each bias estimate).
//     Pairs whose residual exceeds `outlier_factor` x the median (and 0.1 deg) are dropped once
//     and the solve repeated (odometry glitches).
//  4. Translation (body poses only; a gyroscope carries none): (R_A_k - I) t_X = R_X t_B_k - t_A_k
//     stacked over all pairs, least squares by SVD. Rotation about one axis only (a ground
//     vehicle turning about its vertical) leaves t_X along that axis unobservable: that
//     component is kept from `prior_translation` and the axis is reported.
//
// Frames and units: sensor poses are T_odom_sensor (any fixed odom frame of the sensor's own
// odometry); body poses are T_world_body; the gyroscope is the body's angular velocity in the
// body frame (rad/s), i.e. the IMU defines the body. Poses must be metric (monocular visual
// odometry's unknown scale breaks step 4).
//
// Failure cases (errors naming the cause; those about the input or the configuration also
// carry its field, e.g. "sensor_poses[12]", those about the motion none): empty or single-pose inputs, non-finite values,
// timestamps that do not increase, both or neither of body poses / gyroscope, body and sensor
// time ranges that do not overlap by at least min_pairs pairs (with the offset margin), fewer
// than `min_pairs` pairs that turn, rotation about one axis only (R_X is then unobservable
// about it: turn about a second axis), a bad configuration.
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"

namespace hanzo::fusion::calib {

struct StampedPose {
  Timestamp time;
  SE3 pose;
};

struct GyroSample {
  Timestamp time;
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();  // rad/s, body frame
};

struct MotionCalibrationInput {
  std::string sensor;                    // the calibration entry's name ("lidar" -> lidar_to_body)
  std::vector<StampedPose> sensor_poses;  // T_odom_sensor, sensor clock, increasing times
  /// The body's motion, exactly one of the two: T_world_body (body clock, increasing) ...
  std::vector<StampedPose> body_poses;
  /// ... or the body IMU's gyroscope (body clock, increasing). Rotation and time offset only.
  std::vector<GyroSample> body_gyro;
};

struct MotionCalibrationConfig {
  /// Seconds between the two sensor poses of a pair (consecutive poses at least this far
  /// apart). Longer pairs turn more (better rotation signal) but blur the time offset.
  double pair_interval = 0.2;
  /// Pairs turning less than this (rad) are left out of the rotation solve (no axis to align).
  double min_pair_rotation = 0.02;
  /// Pairs needed (those that turn, for the rotation).
  std::size_t min_pairs = 10;
  bool estimate_time_offset = true;
  /// Offsets searched, both ways (s); also the margin at both ends of the data.
  double max_time_offset = 0.2;
  /// Coarse scan step of the offset search (s).
  double time_offset_step = 0.002;
  /// Used when estimate_time_offset is false, and as the scan's centre otherwise.
  Duration initial_time_offset;
  /// Gyroscope input only: estimate a constant gyroscope bias alongside R_X.
  bool estimate_gyro_bias = true;
  /// A pair whose rotation residual exceeds this many times the median is an outlier.
  double outlier_factor = 3.0;
  /// Square root of the second largest over the largest singular value of sum a_k b_k^T (about
  /// the ratio of the second axis' rotation to the first's) below which the motion is treated
  /// as rotation about one axis (R_X unobservable about it).
  double min_rotation_axis_spread = 0.02;
  /// Smallest over largest singular value of the translation system below which the weakest
  /// direction is unobservable and kept from prior_translation.
  double min_translation_observability = 0.05;
  /// t_X's value in directions the motion does not observe (m, body frame).
  Eigen::Vector3d prior_translation = Eigen::Vector3d::Zero();
};

struct MotionCalibrationSummary {
  /// The result: sensor name, R_body_sensor, translation (the prior where not estimated), offset.
  SensorCalibration calibration;
  bool translation_estimated = false;  // false with a gyroscope
  /// Body-frame axis along which the translation was not observable (kept from the prior).
  std::optional<Eigen::Vector3d> unobservable_translation_axis;
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();  // rad/s, gyroscope input with estimate_gyro_bias
  std::size_t pairs = 0;                // relative motions formed
  std::size_t rotation_pairs = 0;       // of those, turning enough for the rotation solve
  std::size_t outlier_pairs = 0;        // dropped as outliers
  double rotation_residual_rms_deg = 0.0;     // |log(R_A^-1 R_X R_B R_X^-1)| over the rotation pairs
  double translation_residual_rms_m = 0.0;    // |(R_A - I) t_X - R_X t_B + t_A| over all pairs
  double rotation_axis_spread = 0.0;          // see min_rotation_axis_spread (1: rich 3D motion)
  double translation_observability = 0.0;     // see min_translation_observability
};

Result<MotionCalibrationSummary> calibrate_from_motion(const MotionCalibrationInput& input,
                                                       const MotionCalibrationConfig& config = {});

}  // namespace hanzo::fusion::calib
