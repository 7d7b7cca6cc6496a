#include "hanzo/fusion/estimate/position_models.hpp"

namespace hanzo::fusion::estimate {

MeasurementVector GnssPositionModel::residual(const NavigationState& state, MeasurementJacobian* jacobian) const {
  const Eigen::Matrix3d R = state.R_world_body.matrix();
  MeasurementVector r = measured_ - (state.position + R * p_body_antenna_);
  if (jacobian != nullptr) {
    jacobian->setZero(3, kErrorStateDimension);
    jacobian->block<3, 3>(0, kPositionIndex).setIdentity();
    jacobian->block<3, 3>(0, kOrientationIndex) = -R * SO3::hat(p_body_antenna_);
  }
  return r;
}

MeasurementVector PoseModel::residual(const NavigationState& state, MeasurementJacobian* jacobian) const {
  const Eigen::Matrix3d R = state.R_world_body.matrix();
  const SO3 predicted_rotation = state.R_world_body * T_body_sensor_.rotation();
  const Eigen::Vector3d rotation_residual = (predicted_rotation.inverse() * measured_.rotation()).log();
  MeasurementVector r(6);
  r.head<3>() = measured_.translation() - (state.position + R * T_body_sensor_.translation());
  r.tail<3>() = rotation_residual;
  if (jacobian != nullptr) {
    jacobian->setZero(6, kErrorStateDimension);
    jacobian->block<3, 3>(0, kPositionIndex).setIdentity();
    jacobian->block<3, 3>(0, kOrientationIndex) = -R * SO3::hat(T_body_sensor_.translation());
    jacobian->block<3, 3>(3, kOrientationIndex) =
        SO3::left_jacobian_inverse(rotation_residual) * T_body_sensor_.rotation().matrix().transpose();
  }
  return r;
}

}  // namespace hanzo::fusion::estimate
