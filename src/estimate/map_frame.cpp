#include "hanzo/fusion/estimate/map_frame.hpp"

namespace hanzo::fusion::estimate {

MapFrameAnchor MapFrameAnchor::plus(const Eigen::Matrix<double, 6, 1>& delta) const {
  MapFrameAnchor out = *this;
  out.T_world_anchor = SE3(T_world_anchor.rotation() * SO3::exp(delta.tail<3>()), T_world_anchor.translation() + delta.head<3>());
  return out;
}

MapPoseModel::Vector6 MapPoseModel::residual(const NavigationState& state, const MapFrameAnchor& anchor, StateJacobian* H_state,
                                             Matrix6* H_anchor) const {
  const SE3 T_world_map = anchor.T_world_map();
  const Eigen::Matrix3d R_map_world = T_world_map.rotation().matrix().transpose();
  const Eigen::Matrix3d R_world_body = state.R_world_body.matrix();
  const Eigen::Vector3d sensor_world = state.position + R_world_body * T_body_sensor_.translation();
  const Eigen::Vector3d predicted_position = R_map_world * (sensor_world - T_world_map.translation());
  const SO3 predicted_rotation = T_world_map.rotation().inverse() * state.R_world_body * T_body_sensor_.rotation();
  Vector6 r;
  r.head<3>() = measured_.translation() - predicted_position;
  r.tail<3>() = (predicted_rotation.inverse() * measured_.rotation()).log();
  const Eigen::Matrix3d rotation_by_perturbation = SO3::left_jacobian_inverse(r.tail<3>());
  if (H_state != nullptr) {
    H_state->setZero();
    H_state->block<3, 3>(0, kPositionIndex) = R_map_world;
    H_state->block<3, 3>(0, kOrientationIndex) = -R_map_world * R_world_body * SO3::hat(T_body_sensor_.translation());
    H_state->block<3, 3>(3, kOrientationIndex) = rotation_by_perturbation * T_body_sensor_.rotation().matrix().transpose();
  }
  if (H_anchor != nullptr) {
    // The map frame's error (dq world, dphi map frame) from the anchor's: dphi = R_am^T dtheta,
    // dq = dp - R_wa [t_am]x dtheta; h_p moves by -R_mw dq + [h_p]x dphi, h_R by Exp(-h_R^T dphi).
    const Eigen::Matrix3d R_map_anchor = anchor.T_anchor_map.rotation().matrix().transpose();
    const Eigen::Matrix3d R_world_anchor = anchor.T_world_anchor.rotation().matrix();
    H_anchor->block<3, 3>(0, 0) = -R_map_world;
    H_anchor->block<3, 3>(0, 3) = R_map_world * R_world_anchor * SO3::hat(anchor.T_anchor_map.translation()) +
                                  SO3::hat(predicted_position) * R_map_anchor;
    H_anchor->block<3, 3>(3, 0).setZero();
    H_anchor->block<3, 3>(3, 3) = -rotation_by_perturbation * predicted_rotation.matrix().transpose() * R_map_anchor;
  }
  return r;
}

}  // namespace hanzo::fusion::estimate
