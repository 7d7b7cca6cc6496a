#include "hanzo/fusion/estimate/error_state_ekf.hpp"

#include <cmath>

#include <Eigen/Cholesky>

namespace hanzo::fusion::estimate {

ErrorStateEkf::ErrorStateEkf(const FilterConfig& config) : config_(config), gate_(config.gate_probability) {}

void ErrorStateEkf::reset(const NavigationState& state, const ErrorCovariance& covariance) {
  state_ = state;
  covariance_ = covariance;
  clone_.reset();
}

void ErrorStateEkf::clone_pose() {
  PoseClone clone;
  clone.covariance = covariance_.topLeftCorner<6, 6>();
  clone.cross = covariance_.topRows<6>();
  clone_ = clone;
}

void ErrorStateEkf::apply_world_transform(const SE3& T_correction) {
  transform_in_world(T_correction, state_, &covariance_);
  clone_.reset();  // the clone's frame moved: the next keyframe starts afresh
}

void ErrorStateEkf::predict(const ImuSample& sample, double dt) {
  if (dt <= 0.0) return;
  ImuTransition transition;
  state_ = propagate_state(state_, body_motion(state_, sample, config_.imu_mounting), dt, config_.imu_mounting, &transition);
  propagate_covariance(covariance_, transition, config_.imu_noise);
  if (clone_) multiply_by_transition_transpose(clone_->cross, transition);
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
  using GainMatrix = Eigen::Matrix<double, kErrorStateDimension, M>;
  using Square = Eigen::Matrix<double, M, M>;
  UpdateOutcome outcome;
  MeasurementJacobian H_dynamic;
  outcome.innovation = model.residual(state_, &H_dynamic);
  outcome.gate = gate_.threshold(M);
  const Eigen::Matrix<double, M, kErrorStateDimension> H = H_dynamic;
  const Eigen::Matrix<double, M, 1> r = outcome.innovation;

  const GainMatrix PHt = covariance_ * H.transpose();
  const Square S = H * PHt + Square(model.covariance());
  const Eigen::LLT<Square> llt(S);
  if (!passes_gate(llt, r, apply_gate, outcome)) return outcome;
  // K = P H^T S^-1, computed as (S^-1 H P)^T (S symmetric).
  const GainMatrix K = llt.solve(PHt.transpose()).transpose();
  const ErrorVector delta = K * r;
  const NavigationState updated = state_.plus(delta);
  if (!updated.all_finite()) {
    outcome.status = UpdateStatus::kNumericalFailure;
    return outcome;
  }
  state_ = updated;
  covariance_.noalias() -= K * PHt.transpose();  // K S K^T = P H^T S^-1 H P = K (P H^T)^T
  if (clone_) {
    const Eigen::Matrix<double, 6, M> CHt = clone_->cross * H.transpose();  // = Kc S
    const Eigen::Matrix<double, 6, M> clone_gain = llt.solve(CHt.transpose()).transpose();
    clone_->correction += clone_gain * r;
    clone_->covariance -= clone_gain * CHt.transpose();
    clone_->cross -= CHt * K.transpose();
  }
  // Error reset: the orientation error is now measured from the corrected orientation.
  const Eigen::Matrix3d G = Eigen::Matrix3d::Identity() - SO3::hat(0.5 * delta.template segment<3>(kOrientationIndex));
  covariance_.middleRows<3>(kOrientationIndex) = (G * covariance_.middleRows<3>(kOrientationIndex)).eval();
  covariance_.middleCols<3>(kOrientationIndex) = (covariance_.middleCols<3>(kOrientationIndex) * G.transpose()).eval();
  if (clone_) clone_->cross.middleCols<3>(kOrientationIndex) = (clone_->cross.middleCols<3>(kOrientationIndex) * G.transpose()).eval();
  symmetrize(covariance_);
  return outcome;
}

}  // namespace hanzo::fusion::estimate
