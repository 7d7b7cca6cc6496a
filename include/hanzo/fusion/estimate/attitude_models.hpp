#pragma once
// Measurement models of orientation and gravity (measurement_model.hpp for the contract).

#include <array>

#include <Eigen/Core>

#include "hanzo/fusion/core/so3.hpp"
#include "hanzo/fusion/estimate/measurement_model.hpp"

namespace hanzo::fusion::estimate {

/// Roll, pitch, yaw of R (ZYX convention: R = Rz(yaw) Ry(pitch) Rx(roll)), radians; pitch in
/// [-pi/2, pi/2], roll and yaw in [-pi, pi].
Eigen::Vector3d roll_pitch_yaw(const Eigen::Matrix3d& R);
/// W with d(roll, pitch, yaw) = W dtheta for R -> R Exp(dtheta) (body rates to Euler rates);
/// singular at pitch = +-90 degrees.
Eigen::Matrix3d euler_rates_from_body_rates(const Eigen::Vector3d& roll_pitch_yaw);

/// The orientation an IMU (AHRS) reports, R_world_imu, fused per Euler angle as
/// robot_localization users configure it: any of roll, pitch, yaw may be selected (yaw only
/// when the IMU's heading reference is the world's: magnetometer-referenced north, or a world
/// frame defined by the IMU as in robot_localization's odom frame).
///   h(x) = selected angles of R R_body_imu;  residual = wrap(z - h) per angle
///   H    = rows of W(h) R_body_imu^T in the orientation block
/// covariance: the message's rotation-vector covariance Sigma (IMU frame, rad^2) mapped to
/// Euler angles, W Sigma W^T, selected entries.
/// Near gimbal lock (|cos pitch| < 0.1) the angles are ill-defined: usable() is false there and
/// the caller must not fuse it.
class ImuAttitudeModel final : public MeasurementModel {
 public:
  ImuAttitudeModel(const SO3& R_world_imu_measured, const Eigen::Matrix3d& rotation_covariance, const SO3& R_body_imu,
                   std::array<bool, 3> use_roll_pitch_yaw);

  bool usable() const;
  std::string_view name() const override { return "imu_attitude"; }
  int dimension() const override { return count_; }
  MeasurementVector residual(const NavigationState& state, MeasurementJacobian* jacobian) const override;
  MeasurementCovariance covariance() const override;

 private:
  Eigen::Vector3d measured_angles_;
  Eigen::Matrix3d angle_covariance_;
  SO3 R_body_imu_;
  std::array<bool, 3> selected_;
  int count_ = 0;
};

/// |g| = magnitude (default standard gravity): h = |g|, H = g^T / |g| in the gravity block.
class GravityMagnitudeModel final : public MeasurementModel {
 public:
  GravityMagnitudeModel(double magnitude, double sigma) : magnitude_(magnitude), sigma_(sigma) {}
  std::string_view name() const override { return "gravity_magnitude"; }
  int dimension() const override { return 1; }
  MeasurementVector residual(const NavigationState& state, MeasurementJacobian* jacobian) const override;
  MeasurementCovariance covariance() const override { return MeasurementCovariance::Constant(1, 1, sigma_ * sigma_); }

 private:
  double magnitude_;
  double sigma_;
};

/// Planar motion (ground robot on a flat floor, robot_localization's two_d_mode): the body
/// stays at height z0 with no vertical velocity. h = (p_z, v_z).
class PlanarMotionModel final : public MeasurementModel {
 public:
  PlanarMotionModel(double height, double height_sigma, double vertical_speed_sigma)
      : height_(height), height_sigma_(height_sigma), vertical_speed_sigma_(vertical_speed_sigma) {}
  std::string_view name() const override { return "planar_motion"; }
  int dimension() const override { return 2; }
  MeasurementVector residual(const NavigationState& state, MeasurementJacobian* jacobian) const override;
  MeasurementCovariance covariance() const override;

 private:
  double height_;
  double height_sigma_;
  double vertical_speed_sigma_;
};

}  // namespace hanzo::fusion::estimate
