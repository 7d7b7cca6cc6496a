#pragma once
// Exact motion for calibration tests: a body swinging about three axes while it moves, a sensor
// rigidly attached with a known T_body_sensor and clock offset, its noisy odometry, and the
// body's poses or its biased, noisy gyroscope.

#include <cmath>
#include <random>
#include <vector>

#include "hanzo/fusion/calib/motion_calibration.hpp"
#include "hanzo/fusion/core/so3.hpp"

namespace hanzo::fusion::test_support {

using calib::GyroSample;
using calib::StampedPose;

inline constexpr double kDegToRad = M_PI / 180.0;
inline const Timestamp kStart = Timestamp::from_seconds(1700000000.0);

// A body swinging about all three axes while it moves: R_world_body = Exp(phi(t)), so its
// body-frame angular velocity is J_r(phi) phi'(t) exactly. `roll_pitch` scales the swing
// about x and y (0: it turns about its vertical only).
struct BodyTrajectory {
  double roll_pitch = 1.0;

  Eigen::Vector3d phi(double t) const {
    return {roll_pitch * 0.5 * std::sin(1.3 * t), roll_pitch * 0.4 * std::sin(0.9 * t + 1.0), 1.2 * std::sin(0.45 * t)};
  }
  Eigen::Vector3d phi_rate(double t) const {
    return {roll_pitch * 0.65 * std::cos(1.3 * t), roll_pitch * 0.36 * std::cos(0.9 * t + 1.0), 0.54 * std::cos(0.45 * t)};
  }
  SE3 pose(double t) const {
    return SE3(SO3::exp(phi(t)), Eigen::Vector3d(3.0 * std::sin(0.3 * t), 2.0 * std::cos(0.4 * t) - 2.0, 0.4 * std::sin(0.7 * t)));
  }
  Eigen::Vector3d angular_velocity(double t) const { return SO3::right_jacobian(phi(t)) * phi_rate(t); }
};

struct CalibrationScenario {
  BodyTrajectory body;
  SE3 T_body_sensor{SO3::exp(Eigen::Vector3d(0.3, -1.2, 2.0)), Eigen::Vector3d(0.12, -0.05, 0.30)};
  double time_offset = -0.0237;  // t_body = t_sensor + offset
  double duration = 60.0;
  double sensor_rate = 10.0;
  double sensor_position_noise = 0.001;             // m
  double sensor_rotation_noise = 0.05 * kDegToRad;  // rad
  Eigen::Vector3d gyro_bias{0.010, -0.020, 0.005};  // rad/s
  double gyro_noise = 0.005;                        // rad/s per sample
  std::mt19937 random{7};

  // The sensor's own odometry: T_odom_sensor(t_s) = T_odom_world T_world_body(t_s + offset) X, noisy.
  std::vector<StampedPose> sensor_poses() {
    std::normal_distribution<double> normal;
    const SE3 T_odom_world(SO3::exp(Eigen::Vector3d(0.2, 0.1, -0.7)), Eigen::Vector3d(5.0, -3.0, 1.0));
    std::vector<StampedPose> poses;
    for (double t = 0.5; t < duration - 0.5; t += 1.0 / sensor_rate) {
      SE3 pose = T_odom_world * body.pose(t + time_offset) * T_body_sensor;
      const Eigen::Vector3d rotation_noise(normal(random), normal(random), normal(random));
      const Eigen::Vector3d position_noise(normal(random), normal(random), normal(random));
      pose = SE3(pose.rotation() * SO3::exp(rotation_noise * sensor_rotation_noise),
                 pose.translation() + position_noise * sensor_position_noise);
      poses.push_back({kStart + Duration::from_seconds(t), pose});
    }
    return poses;
  }
  std::vector<StampedPose> body_poses(double rate = 100.0) const {
    std::vector<StampedPose> poses;
    for (double t = 0.0; t <= duration; t += 1.0 / rate) poses.push_back({kStart + Duration::from_seconds(t), body.pose(t)});
    return poses;
  }
  std::vector<GyroSample> gyro(double rate = 200.0) {
    std::normal_distribution<double> normal;
    std::vector<GyroSample> samples;
    for (double t = 0.0; t <= duration; t += 1.0 / rate) {
      const Eigen::Vector3d noise(normal(random), normal(random), normal(random));
      samples.push_back({kStart + Duration::from_seconds(t), body.angular_velocity(t) + gyro_bias + noise * gyro_noise});
    }
    return samples;
  }
};

}  // namespace hanzo::fusion::test_support
