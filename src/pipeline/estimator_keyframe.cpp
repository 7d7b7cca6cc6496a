// Estimator: keyframes for the backend (pose, relative motion and its covariance).

#include "estimator.hpp"

namespace hanzo::fusion::pipeline {

using estimate::ErrorCovariance;
using estimate::NavigationState;

std::optional<msgs::Keyframe> Estimator::maybe_keyframe(Timestamp time) {
  // Until the GNSS course gives the heading, the poses' world frame is not known: the backend
  // gets no keyframes (their motion would include the heading's alignment as a jump).
  if (heading_pending_) return std::nullopt;
  if (last_keyframe_ && (time - last_keyframe_->time).seconds() < frontend_.keyframe_interval()) return std::nullopt;
  const NavigationState state = filter_->state();
  const ErrorCovariance P = filter_->covariance();
  const SE3 T_world_body(state.R_world_body, state.position);
  msgs::Keyframe keyframe;
  keyframe.keyframe_id = last_keyframe_ ? last_keyframe_->id + 1 : 0;
  keyframe.timestamp = time;
  keyframe.T_world_body = msgs::Pose::from_se3(T_world_body);
  keyframe.velocity = state.velocity;
  keyframe.pose_covariance = P.topLeftCorner<6, 6>();
  if (last_keyframe_) {
    // The previous keyframe's pose as later measurements corrected it (smoothed clone), and the
    // joint covariance of the two poses' errors.
    const std::optional<estimate::PoseClone> clone = filter_->pose_clone();
    SE3 T_world_previous = last_keyframe_->T_world_body;
    Eigen::Matrix<double, 12, 12> joint = Eigen::Matrix<double, 12, 12>::Zero();
    joint.topLeftCorner<6, 6>() = last_keyframe_->covariance;
    if (clone) {
      T_world_previous = SE3(T_world_previous.rotation() * SO3::exp(clone->correction.tail<3>()),
                             T_world_previous.translation() + clone->correction.head<3>());
      joint.topLeftCorner<6, 6>() = clone->covariance;
      joint.topRightCorner<6, 6>() = clone->cross.leftCols<6>();
      joint.bottomLeftCorner<6, 6>() = clone->cross.leftCols<6>().transpose();
    }
    joint.bottomRightCorner<6, 6>() = P.topLeftCorner<6, 6>();
    // T_rel = T_a^-1 T_b, tangent (rho, phi) with T_rel_true = T_rel Exp(rho, phi); errors of a
    // and b are (position world, orientation body):
    //   d rho = R_b^T dp_b - R_rel^T R_a^T dp_a + R_rel^T [p_rel]x dtheta_a,  d phi = dtheta_b - R_rel^T dtheta_a.
    const SE3 T_relative = T_world_previous.inverse() * T_world_body;
    const Eigen::Matrix3d R_a = T_world_previous.rotation().matrix();
    const Eigen::Matrix3d R_b = state.R_world_body.matrix();
    const Eigen::Matrix3d R_rel_t = T_relative.rotation().matrix().transpose();
    Eigen::Matrix<double, 6, 12> J = Eigen::Matrix<double, 6, 12>::Zero();
    J.block<3, 3>(0, 0) = -R_rel_t * R_a.transpose();
    J.block<3, 3>(0, 3) = R_rel_t * SO3::hat(T_relative.translation());
    J.block<3, 3>(0, 6) = R_b.transpose();
    J.block<3, 3>(3, 3) = -R_rel_t;
    J.block<3, 3>(3, 9) = Eigen::Matrix3d::Identity();
    keyframe.previous_keyframe_id = last_keyframe_->id;
    keyframe.T_previous_current = msgs::Pose::from_se3(T_relative);
    msgs::Matrix6d relative = J * joint * J.transpose();
    keyframe.relative_covariance = 0.5 * (relative + relative.transpose());
  }
  filter_->clone_pose();
  last_keyframe_ = KeyframeAnchor{keyframe.keyframe_id, time, T_world_body, P.topLeftCorner<6, 6>()};
  return keyframe;
}

}  // namespace hanzo::fusion::pipeline
