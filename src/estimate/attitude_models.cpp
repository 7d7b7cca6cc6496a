#include "hanzo/fusion/estimate/attitude_models.hpp"

#include <cmath>
#include <numbers>

namespace hanzo::fusion::estimate {
namespace {

double wrap_angle(double angle) { return std::remainder(angle, 2.0 * std::numbers::pi); }

constexpr double kMinimumCosinePitch = 0.1;

}  // namespace

Eigen::Vector3d roll_pitch_yaw(const Eigen::Matrix3d& R) {
  return {std::atan2(R(2, 1), R(2, 2)), std::asin(std::clamp(-R(2, 0), -1.0, 1.0)), std::atan2(R(1, 0), R(0, 0))};
}

Eigen::Matrix3d euler_rates_from_body_rates(const Eigen::Vector3d& rpy) {
  const double sr = std::sin(rpy.x());
  const double cr = std::cos(rpy.x());
  const double cp = std::cos(rpy.y());
  const double tp = std::tan(rpy.y());
  Eigen::Matrix3d W;
  W << 1.0, sr * tp, cr * tp,  //
      0.0, cr, -sr,            //
      0.0, sr / cp, cr / cp;
  return W;
}

ImuAttitudeModel::ImuAttitudeModel(const SO3& R_world_imu_measured, const Eigen::Matrix3d& rotation_covariance,
                                   const SO3& R_body_imu, std::array<bool, 3> use_roll_pitch_yaw)
    : measured_angles_(roll_pitch_yaw(R_world_imu_measured.matrix())),
      R_body_imu_(R_body_imu),
      selected_(use_roll_pitch_yaw) {
  for (bool selected : selected_) count_ += selected ? 1 : 0;
  const Eigen::Matrix3d W = euler_rates_from_body_rates(measured_angles_);
  angle_covariance_ = W * rotation_covariance * W.transpose();
}

bool ImuAttitudeModel::usable() const { return count_ > 0 && std::abs(std::cos(measured_angles_.y())) >= kMinimumCosinePitch; }

MeasurementVector ImuAttitudeModel::residual(const NavigationState& state, MeasurementJacobian* jacobian) const {
  const Eigen::Matrix3d R_world_imu = state.R_world_body.matrix() * R_body_imu_.matrix();
  const Eigen::Vector3d predicted = roll_pitch_yaw(R_world_imu);
  Eigen::Matrix3d angles_by_orientation;
  if (jacobian != nullptr) {
    angles_by_orientation = euler_rates_from_body_rates(predicted) * R_body_imu_.matrix().transpose();
    jacobian->setZero(count_, kErrorStateDimension);
  }
  MeasurementVector r(count_);
  int row = 0;
  for (int angle = 0; angle < 3; ++angle) {
    if (!selected_[static_cast<size_t>(angle)]) continue;
    r(row) = wrap_angle(measured_angles_(angle) - predicted(angle));
    if (jacobian != nullptr) jacobian->block<1, 3>(row, kOrientationIndex) = angles_by_orientation.row(angle);
    ++row;
  }
  return r;
}

MeasurementCovariance ImuAttitudeModel::covariance() const {
  MeasurementCovariance out(count_, count_);
  int row = 0;
  for (int i = 0; i < 3; ++i) {
    if (!selected_[static_cast<size_t>(i)]) continue;
    int column = 0;
    for (int j = 0; j < 3; ++j) {
      if (!selected_[static_cast<size_t>(j)]) continue;
      out(row, column++) = angle_covariance_(i, j);
    }
    ++row;
  }
  return out;
}

MeasurementVector GravityMagnitudeModel::residual(const NavigationState& state, MeasurementJacobian* jacobian) const {
  const double norm = state.gravity.norm();
  if (jacobian != nullptr) {
    jacobian->setZero(1, kErrorStateDimension);
    jacobian->block<1, 3>(0, kGravityIndex) = state.gravity.transpose() / norm;
  }
  return MeasurementVector::Constant(1, magnitude_ - norm);
}

MeasurementVector PlanarMotionModel::residual(const NavigationState& state, MeasurementJacobian* jacobian) const {
  if (jacobian != nullptr) {
    jacobian->setZero(2, kErrorStateDimension);
    (*jacobian)(0, kPositionIndex + 2) = 1.0;
    (*jacobian)(1, kVelocityIndex + 2) = 1.0;
  }
  MeasurementVector r(2);
  r << height_ - state.position.z(), -state.velocity.z();
  return r;
}

MeasurementCovariance PlanarMotionModel::covariance() const {
  MeasurementCovariance out = MeasurementCovariance::Zero(2, 2);
  out(0, 0) = height_sigma_ * height_sigma_;
  out(1, 1) = vertical_speed_sigma_ * vertical_speed_sigma_;
  return out;
}

}  // namespace hanzo::fusion::estimate
