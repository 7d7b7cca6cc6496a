#include "hanzo/fusion/estimate/error_state_ekf.hpp"

#include <cmath>

#include <Eigen/Cholesky>

namespace hanzo::fusion::estimate {

ErrorStateEkf::ErrorStateEkf(const FilterConfig& config) : config_(config), gate_(config.gate_probability) {}

void ErrorStateEkf::reset(const NavigationState& state, const ErrorCovariance& covariance) {
  state_ = state;
  covariance_ = covariance;
  clone_.reset();
  anchors_.clear();
  anchor_covariance_.resize(0, 0);
  anchor_cross_.resize(0, kErrorStateDimension);
  clone_anchor_cross_.resize(6, 0);
}

void ErrorStateEkf::clone_pose() {
  PoseClone clone;
  clone.covariance = covariance_.topLeftCorner<6, 6>();
  clone.cross = covariance_.topRows<6>();
  clone_ = clone;
  clone_anchor_cross_ = anchor_cross_.leftCols<6>().transpose();
}

std::optional<int> ErrorStateEkf::add_map_frame(const SE3& T_body_map) {
  // The anchor is a clone of the body pose: its error is the pose's, correlated as the pose is.
  const auto n = static_cast<Eigen::Index>(6 * anchors_.size());
  Eigen::MatrixXd covariance = Eigen::MatrixXd::Zero(n + 6, n + 6);
  covariance.topLeftCorner(n, n) = anchor_covariance_;
  covariance.block(n, 0, 6, n) = anchor_cross_.leftCols<6>().transpose();
  covariance.block(0, n, n, 6) = anchor_cross_.leftCols<6>();
  covariance.bottomRightCorner<6, 6>() = covariance_.topLeftCorner<6, 6>();
  anchor_covariance_ = std::move(covariance);
  anchor_cross_.conservativeResize(n + 6, Eigen::NoChange);
  anchor_cross_.bottomRows<6>() = covariance_.topRows<6>();
  clone_anchor_cross_.conservativeResize(Eigen::NoChange, n + 6);
  clone_anchor_cross_.rightCols<6>() = clone_ ? Eigen::Matrix<double, 6, 6>(clone_->cross.leftCols<6>()) : Eigen::Matrix<double, 6, 6>::Zero();
  anchors_.push_back({SE3(state_.R_world_body, state_.position), T_body_map});
  return static_cast<int>(anchors_.size()) - 1;
}

std::optional<SE3> ErrorStateEkf::map_frame(int frame) const {
  if (frame < 0 || frame >= static_cast<int>(anchors_.size())) return std::nullopt;
  return anchors_[static_cast<size_t>(frame)].T_world_map();
}

void ErrorStateEkf::apply_world_transform(const SE3& T_correction) {
  transform_in_world(T_correction, state_, &covariance_);
  clone_.reset();  // the clone's frame moved: the next keyframe starts afresh
  // Anchors move with the world: their positions' errors rotate (world frame), their
  // orientations' do not (anchor frame); the state's position and velocity errors rotate.
  const Eigen::Matrix3d R = T_correction.rotation().matrix();
  for (size_t k = 0; k < anchors_.size(); ++k) {
    anchors_[k].T_world_anchor = T_correction * anchors_[k].T_world_anchor;
    const auto row = static_cast<Eigen::Index>(6 * k);
    anchor_cross_.middleRows<3>(row) = (R * anchor_cross_.middleRows<3>(row)).eval();
    anchor_covariance_.middleRows(row, 3) = (R * anchor_covariance_.middleRows(row, 3)).eval();
    anchor_covariance_.middleCols(row, 3) = (anchor_covariance_.middleCols(row, 3) * R.transpose()).eval();
  }
  for (const int index : {kPositionIndex, kVelocityIndex}) {
    anchor_cross_.middleCols<3>(index) = (anchor_cross_.middleCols<3>(index) * R.transpose()).eval();
  }
}

void ErrorStateEkf::predict(const ImuSample& sample, double dt) {
  if (dt <= 0.0) return;
  ImuTransition transition;
  state_ = propagate_state(state_, body_motion(state_, sample, config_.imu_mounting), dt, config_.imu_mounting, &transition);
  propagate_covariance(covariance_, transition, config_.imu_noise);
  if (clone_) multiply_by_transition_transpose(clone_->cross, transition);
  if (!anchors_.empty()) multiply_by_transition_transpose(anchor_cross_, transition);
}

UpdateOutcome ErrorStateEkf::update(const MeasurementModel& model, bool apply_gate) {
  // Fixed-size matrices per measurement dimension: about 2x faster than dynamic sizes.
  switch (model.dimension()) {
    case 1: return update_fixed<1>(model, apply_gate);
    case 2: return update_fixed<2>(model, apply_gate);
    case 3: return update_fixed<3>(model, apply_gate);
    case 4: return update_fixed<4>(model, apply_gate);
    case 5: return update_fixed<5>(model, apply_gate);
    default: return update_fixed<6>(model, apply_gate);
  }
}

template <int M>
UpdateOutcome ErrorStateEkf::update_fixed(const MeasurementModel& model, bool apply_gate) {
  UpdateOutcome outcome;
  MeasurementJacobian H_dynamic;
  outcome.innovation = model.residual(state_, &H_dynamic);
  const Eigen::Matrix<double, M, kErrorStateDimension> H = H_dynamic;
  const Eigen::Matrix<double, M, 1> r = outcome.innovation;
  return update_augmented<M>(r, H, nullptr, -1, model.covariance(), apply_gate, std::move(outcome));
}

UpdateOutcome ErrorStateEkf::update_map_pose(const MapPoseModel& model, bool apply_gate) {
  UpdateOutcome outcome;
  if (model.frame() < 0 || model.frame() >= static_cast<int>(anchors_.size())) {
    outcome.status = UpdateStatus::kNumericalFailure;
    return outcome;
  }
  MapPoseModel::StateJacobian H;
  MapPoseModel::Matrix6 H_anchor;
  const MapPoseModel::Vector6 r = model.residual(state_, anchors_[static_cast<size_t>(model.frame())], &H, &H_anchor);
  outcome.innovation = r;
  return update_augmented<6>(r, H, &H_anchor, model.frame(), model.covariance(), apply_gate, std::move(outcome));
}

template <int M>
UpdateOutcome ErrorStateEkf::update_augmented(const Eigen::Matrix<double, M, 1>& r, const Eigen::Matrix<double, M, kErrorStateDimension>& H,
                                              const Eigen::Matrix<double, M, 6>* H_anchor, int frame,
                                              const Eigen::Matrix<double, M, M>& R, bool apply_gate, UpdateOutcome outcome) {
  using GainMatrix = Eigen::Matrix<double, kErrorStateDimension, M>;
  using Square = Eigen::Matrix<double, M, M>;
  using AnchorGain = Eigen::Matrix<double, Eigen::Dynamic, M>;
  outcome.gate = gate_.threshold(M);
  const auto column = static_cast<Eigen::Index>(6 * frame);
  // Cov(y, z) for each block y of [x; anchors; clone] with z = H_full y: U = P_y H_full^T.
  GainMatrix PHt = covariance_ * H.transpose();
  AnchorGain anchor_U = anchor_cross_ * H.transpose();
  Eigen::Matrix<double, 6, M> clone_U;
  if (clone_) clone_U = clone_->cross * H.transpose();
  if (H_anchor != nullptr) {
    PHt.noalias() += anchor_cross_.middleRows<6>(column).transpose() * H_anchor->transpose();
    anchor_U.noalias() += anchor_covariance_.middleCols(column, 6) * H_anchor->transpose();
    if (clone_) clone_U.noalias() += clone_anchor_cross_.middleCols<6>(column) * H_anchor->transpose();
  }
  Square S = H * PHt + R;
  if (H_anchor != nullptr) S.noalias() += *H_anchor * anchor_U.template middleRows<6>(column);
  const Eigen::LLT<Square> llt(S);
  if (!passes_gate(llt, r, apply_gate, outcome)) return outcome;
  // Gains K = U S^-1, computed as (S^-1 U^T)^T (S symmetric).
  const GainMatrix K = llt.solve(PHt.transpose()).transpose();
  const ErrorVector delta = K * r;
  const NavigationState updated = state_.plus(delta);
  if (!updated.all_finite()) {
    outcome.status = UpdateStatus::kNumericalFailure;
    return outcome;
  }
  state_ = updated;
  covariance_.noalias() -= K * PHt.transpose();  // K S K^T = K (P H^T)^T
  Eigen::Matrix<double, 6, M> clone_gain;
  if (clone_) clone_gain = llt.solve(clone_U.transpose()).transpose();
  Eigen::VectorXd anchor_delta;
  if (!anchors_.empty()) {
    const AnchorGain anchor_K = llt.solve(anchor_U.transpose()).transpose();
    anchor_delta = anchor_K * r;
    anchor_cross_.noalias() -= anchor_K * PHt.transpose();
    anchor_covariance_.noalias() -= anchor_K * anchor_U.transpose();
    if (clone_) clone_anchor_cross_.noalias() -= clone_gain * anchor_U.transpose();
  }
  if (clone_) {
    clone_->correction += clone_gain * r;
    clone_->covariance -= clone_gain * clone_U.transpose();
    clone_->cross -= clone_gain * PHt.transpose();
  }
  // Error reset: orientation errors are now measured from the corrected orientations.
  const Eigen::Matrix3d G = Eigen::Matrix3d::Identity() - SO3::hat(0.5 * delta.template segment<3>(kOrientationIndex));
  covariance_.middleRows<3>(kOrientationIndex) = (G * covariance_.middleRows<3>(kOrientationIndex)).eval();
  covariance_.middleCols<3>(kOrientationIndex) = (covariance_.middleCols<3>(kOrientationIndex) * G.transpose()).eval();
  if (clone_) clone_->cross.middleCols<3>(kOrientationIndex) = (clone_->cross.middleCols<3>(kOrientationIndex) * G.transpose()).eval();
  if (!anchors_.empty()) anchor_cross_.middleCols<3>(kOrientationIndex) = (anchor_cross_.middleCols<3>(kOrientationIndex) * G.transpose()).eval();
  for (size_t k = 0; k < anchors_.size(); ++k) {
    const auto row = static_cast<Eigen::Index>(6 * k);
    const Eigen::Matrix<double, 6, 1> anchor_step = anchor_delta.segment<6>(row);
    anchors_[k] = anchors_[k].plus(anchor_step);
    const Eigen::Matrix3d G_anchor = Eigen::Matrix3d::Identity() - SO3::hat(0.5 * anchor_step.tail<3>());
    anchor_cross_.middleRows<3>(row + 3) = (G_anchor * anchor_cross_.middleRows<3>(row + 3)).eval();
    anchor_covariance_.middleRows(row + 3, 3) = (G_anchor * anchor_covariance_.middleRows(row + 3, 3)).eval();
    anchor_covariance_.middleCols(row + 3, 3) = (anchor_covariance_.middleCols(row + 3, 3) * G_anchor.transpose()).eval();
    if (clone_) clone_anchor_cross_.middleCols<3>(row + 3) = (clone_anchor_cross_.middleCols<3>(row + 3) * G_anchor.transpose()).eval();
  }
  symmetrize(covariance_);
  if (!anchors_.empty()) anchor_covariance_ = (0.5 * (anchor_covariance_ + anchor_covariance_.transpose())).eval();
  return outcome;
}

}  // namespace hanzo::fusion::estimate
