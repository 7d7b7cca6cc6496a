#include "hanzo/fusion/estimate/velocity_models.hpp"

#include "hanzo/fusion/estimate/imu_propagation.hpp"

namespace hanzo::fusion::estimate {
namespace {

using Jacobian3 = Eigen::Matrix<double, 3, kErrorStateDimension>;

Eigen::Vector3d body_rate(const NavigationState& state, const GyroReading& gyro, Eigen::Matrix3d* by_gyro_bias = nullptr,
                          Eigen::Vector3d* by_yaw_scale = nullptr) {
  return body_angular_velocity(state, gyro.angular_velocity, gyro.R_body_imu, by_gyro_bias, by_yaw_scale);
}

// v_s(x) and its Jacobian (see velocity_models.hpp).
Eigen::Vector3d sensor_velocity(const NavigationState& state, const SE3& T_body_sensor, const GyroReading& gyro,
                                Jacobian3* jacobian) {
  const Eigen::Matrix3d R_transpose = state.R_world_body.matrix().transpose();
  const Eigen::Matrix3d R_sensor_body = T_body_sensor.rotation().matrix().transpose();
  const Eigen::Vector3d velocity_body = R_transpose * state.velocity;
  const Eigen::Vector3d& lever = T_body_sensor.translation();
  Eigen::Matrix3d rate_by_gyro_bias;
  Eigen::Vector3d rate_by_yaw_scale;
  const bool derivatives = jacobian != nullptr;
  const Eigen::Vector3d rate =
      body_rate(state, gyro, derivatives ? &rate_by_gyro_bias : nullptr, derivatives ? &rate_by_yaw_scale : nullptr);
  if (derivatives) {
    // d(w x l) = -[l]x dw.
    jacobian->setZero();
    jacobian->block<3, 3>(0, kOrientationIndex) = R_sensor_body * SO3::hat(velocity_body);
    jacobian->block<3, 3>(0, kVelocityIndex) = R_sensor_body * R_transpose;
    jacobian->block<3, 3>(0, kGyroBiasIndex) = -R_sensor_body * SO3::hat(lever) * rate_by_gyro_bias;
    jacobian->col(kGyroYawScaleIndex) = -R_sensor_body * SO3::hat(lever) * rate_by_yaw_scale;
  }
  return R_sensor_body * (velocity_body + rate.cross(lever));
}

}  // namespace

MeasurementVector SensorVelocityModel::residual(const NavigationState& state, MeasurementJacobian* jacobian) const {
  Jacobian3 h;
  const Eigen::Vector3d predicted = sensor_velocity(state, T_body_sensor_, gyro_, jacobian ? &h : nullptr);
  if (jacobian != nullptr) *jacobian = h;
  return measured_ - predicted;
}

MeasurementVector WheelOdometryModel::residual(const NavigationState& state, MeasurementJacobian* jacobian) const {
  Jacobian3 h;
  const Eigen::Vector3d velocity = sensor_velocity(state, T_body_wheel_, gyro_, jacobian ? &h : nullptr);
  const int rows = dimension();
  MeasurementVector r(rows);
  if (jacobian != nullptr) jacobian->setZero(rows, kErrorStateDimension);
  int row = 0;
  const bool used[3] = {measurement_.use_speed, measurement_.lateral_constraint, measurement_.vertical_constraint};
  for (int axis = 0; axis < 3; ++axis) {
    if (!used[axis]) continue;
    // The wheels read the forward speed times their scale; the constraints are zero either way.
    const double scale = axis == 0 ? state.wheel_speed_scale : 1.0;
    r(row) = (axis == 0 ? measurement_.forward_speed : 0.0) - scale * velocity(axis);
    if (jacobian != nullptr) {
      jacobian->row(row) = scale * h.row(axis);
      if (axis == 0) (*jacobian)(row, kWheelScaleIndex) = velocity(axis);
    }
    ++row;
  }
  if (measurement_.use_yaw_rate) {
    // Both wheels' distances carry the scale, so their yaw rate does too.
    const Eigen::RowVector3d yaw_axis = T_body_wheel_.rotation().matrix().col(2).transpose();  // z of R_bw^T
    Eigen::Matrix3d rate_by_gyro_bias;
    Eigen::Vector3d rate_by_yaw_scale;
    const bool derivatives = jacobian != nullptr;
    const double yaw_rate =
        yaw_axis.dot(body_rate(state, gyro_, derivatives ? &rate_by_gyro_bias : nullptr, derivatives ? &rate_by_yaw_scale : nullptr));
    // Unequal wheel scales add a turn proportional to the forward speed (heading drift d, rad/m).
    r(row) = measurement_.yaw_rate - state.wheel_speed_scale * yaw_rate - state.wheel_heading_drift * velocity.x();
    if (jacobian != nullptr) {
      jacobian->row(row) = state.wheel_heading_drift * h.row(0);
      jacobian->block<1, 3>(row, kGyroBiasIndex) += state.wheel_speed_scale * yaw_axis * rate_by_gyro_bias;
      (*jacobian)(row, kWheelScaleIndex) = yaw_rate;
      (*jacobian)(row, kGyroYawScaleIndex) += state.wheel_speed_scale * yaw_axis.dot(rate_by_yaw_scale);
      (*jacobian)(row, kWheelHeadingDriftIndex) = velocity.x();
    }
  }
  return r;
}

MeasurementCovariance WheelOdometryModel::covariance() const {
  MeasurementVector sigmas(dimension());
  int row = 0;
  if (measurement_.use_speed) sigmas(row++) = measurement_.forward_speed_sigma;
  if (measurement_.lateral_constraint) sigmas(row++) = measurement_.lateral_speed_sigma;
  if (measurement_.vertical_constraint) sigmas(row++) = measurement_.lateral_speed_sigma;
  if (measurement_.use_yaw_rate) sigmas(row) = measurement_.yaw_rate_sigma;
  return sigmas.array().square().matrix().asDiagonal();
}

MeasurementVector ZeroVelocityModel::residual(const NavigationState& state, MeasurementJacobian* jacobian) const {
  MeasurementVector r(dimension());
  r.head<3>() = -state.velocity;
  if (jacobian != nullptr) {
    jacobian->setZero(dimension(), kErrorStateDimension);
    jacobian->block<3, 3>(0, kVelocityIndex).setIdentity();
  }
  if (with_angular_rate_) {
    Eigen::Matrix3d rate_by_gyro_bias;
    Eigen::Vector3d rate_by_yaw_scale;
    const bool derivatives = jacobian != nullptr;
    r.tail<3>() = -body_rate(state, gyro_, derivatives ? &rate_by_gyro_bias : nullptr, derivatives ? &rate_by_yaw_scale : nullptr);
    if (jacobian != nullptr) {
      jacobian->block<3, 3>(3, kGyroBiasIndex) = rate_by_gyro_bias;
      jacobian->block<3, 1>(3, kGyroYawScaleIndex) = rate_by_yaw_scale;
    }
  }
  return r;
}

MeasurementCovariance ZeroVelocityModel::covariance() const {
  MeasurementVector sigmas(dimension());
  sigmas.head<3>().setConstant(velocity_sigma_);
  if (with_angular_rate_) sigmas.tail<3>().setConstant(angular_rate_sigma_);
  return sigmas.array().square().matrix().asDiagonal();
}

}  // namespace hanzo::fusion::estimate
