#pragma once
// Measurement models of velocity (measurement_model.hpp for the contract).
//
// A sensor mounted at T_body_sensor moves with the sensor-frame velocity
//   v_s(x) = R_body_sensor^T (R^T v + w x t_body_sensor),   w = C R_body_imu (w_m - bg)
// where w_m is the latest gyroscope reading (the body rate is not a state; it comes from the
// IMU with the estimated gyro bias and yaw scale, C as in imu_propagation.hpp). Jacobian blocks:
//   d/dtheta = R_bs^T [R^T v]x,   d/dv = R_bs^T R^T,   d/dbg = R_bs^T [t_bs]x C R_body_imu.

#include <Eigen/Core>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/estimate/measurement_model.hpp"

namespace hanzo::fusion::estimate {

/// The latest gyroscope reading and the IMU's rotation on the body, to form the body rate.
struct GyroReading {
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();  // rad/s, IMU axes, bias not removed
  SO3 R_body_imu;
};

/// Ego-velocity of a sensor in its own axes, all three components (radar Doppler ego-velocity,
/// visual or LiDAR odometry velocity). covariance in (m/s)^2, sensor axes.
class SensorVelocityModel final : public MeasurementModel {
 public:
  SensorVelocityModel(const Eigen::Vector3d& velocity_sensor, const Eigen::Matrix3d& covariance, const SE3& T_body_sensor,
                      const GyroReading& gyro)
      : measured_(velocity_sensor), covariance_(covariance), T_body_sensor_(T_body_sensor), gyro_(gyro) {}

  std::string_view name() const override { return "sensor_velocity"; }
  int dimension() const override { return 3; }
  MeasurementVector residual(const NavigationState& state, MeasurementJacobian* jacobian) const override;
  MeasurementCovariance covariance() const override { return covariance_; }

 private:
  Eigen::Vector3d measured_;
  Eigen::Matrix3d covariance_;
  SE3 T_body_sensor_;
  GyroReading gyro_;
};

/// Differential-drive wheel odometry between two messages: forward speed
/// v = (dL + dR) / (2 dt) and yaw rate w = (dR - dL) / (b dt) of the wheel frame (x forward,
/// z up; calibration "<wheels>_to_body"). Residual entries, in this order:
///   forward speed (when use_speed); lateral speed = 0 when lateral_constraint and vertical speed = 0 when
///   vertical_constraint (the non-holonomic constraint: a wheel does not slide sideways or leave
///   the ground; planar mode drops the vertical one, which contradicts a level-height constraint
///   while the IMU reports pitch); yaw rate when use_yaw_rate
///   (h = s * z-component of R_body_wheel^T w + d * forward speed, with the state's wheel speed
///   scale s and heading drift d: skid-steered bases report yaw rates far off the truth, so it is
///   optional). The forward speed is predicted as s * forward speed.
struct WheelOdometryMeasurement {
  double forward_speed = 0.0;  // m/s
  double yaw_rate = 0.0;       // rad/s
  double forward_speed_sigma = 0.05;  // m/s
  double yaw_rate_sigma = 0.05;       // rad/s
  double lateral_speed_sigma = 0.05;  // m/s, non-holonomic constraint (lateral and vertical)
  bool use_speed = true;
  bool lateral_constraint = true;
  bool vertical_constraint = true;
  bool use_yaw_rate = true;
};

class WheelOdometryModel final : public MeasurementModel {
 public:
  WheelOdometryModel(const WheelOdometryMeasurement& measurement, const SE3& T_body_wheel, const GyroReading& gyro)
      : measurement_(measurement), T_body_wheel_(T_body_wheel), gyro_(gyro) {}

  std::string_view name() const override { return "wheel_odometry"; }
  int dimension() const override {
    return (measurement_.use_speed ? 1 : 0) + (measurement_.lateral_constraint ? 1 : 0) + (measurement_.vertical_constraint ? 1 : 0) +
           (measurement_.use_yaw_rate ? 1 : 0);
  }
  MeasurementVector residual(const NavigationState& state, MeasurementJacobian* jacobian) const override;
  MeasurementCovariance covariance() const override;

 private:
  WheelOdometryMeasurement measurement_;
  SE3 T_body_wheel_;
  GyroReading gyro_;
};

/// Zero-velocity update while the body is known to stand still: v = 0 (world), and with
/// with_angular_rate also w = R_body_imu (w_m - bg) = 0, which observes the gyro bias.
class ZeroVelocityModel final : public MeasurementModel {
 public:
  ZeroVelocityModel(double velocity_sigma, double angular_rate_sigma, bool with_angular_rate, const GyroReading& gyro)
      : velocity_sigma_(velocity_sigma), angular_rate_sigma_(angular_rate_sigma), with_angular_rate_(with_angular_rate), gyro_(gyro) {}

  std::string_view name() const override { return "zero_velocity"; }
  int dimension() const override { return with_angular_rate_ ? 6 : 3; }
  MeasurementVector residual(const NavigationState& state, MeasurementJacobian* jacobian) const override;
  MeasurementCovariance covariance() const override;

 private:
  double velocity_sigma_;
  double angular_rate_sigma_;
  bool with_angular_rate_;
  GyroReading gyro_;
};

}  // namespace hanzo::fusion::estimate
