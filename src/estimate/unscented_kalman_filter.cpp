#include "hanzo/fusion/estimate/unscented_kalman_filter.hpp"

#include <array>
#include <cmath>

#include <Eigen/Cholesky>

namespace hanzo::fusion::estimate {

UnscentedKalmanFilter::UnscentedKalmanFilter(const FilterConfig& config, const UkfConfig& ukf)
    : config_(config), gate_(config.gate_probability) {
  constexpr double n = kErrorStateDimension;
  lambda_ = ukf.alpha * ukf.alpha * (n + ukf.kappa) - n;
  mean_weight_0_ = lambda_ / (n + lambda_);
  covariance_weight_0_ = mean_weight_0_ + (1.0 - ukf.alpha * ukf.alpha + ukf.beta);
  weight_ = 1.0 / (2.0 * (n + lambda_));
}

void UnscentedKalmanFilter::reset(const NavigationState& state, const ErrorCovariance& covariance) {
  state_ = state;
  covariance_ = covariance;
  clone_.reset();
}

void UnscentedKalmanFilter::clone_pose() {
  PoseClone clone;
  clone.covariance = covariance_.topLeftCorner<6, 6>();
  clone.cross = covariance_.topRows<6>();
  clone_ = clone;
}

void UnscentedKalmanFilter::apply_world_transform(const SE3& T_correction) {
  transform_in_world(T_correction, state_, &covariance_);
  clone_.reset();  // the clone's frame moved: the next keyframe starts afresh
}

bool UnscentedKalmanFilter::sigma_offsets(Eigen::Matrix<double, kErrorStateDimension, kSigmaPoints>& offsets) const {
  // Tiny jitter keeps the Cholesky factor defined for states with (near) zero variance, such as
  // the horizontal gravity components.
  const ErrorCovariance scaled = (kErrorStateDimension + lambda_) * (covariance_ + 1e-15 * ErrorCovariance::Identity());
  const Eigen::LLT<ErrorCovariance> llt(scaled);
  if (llt.info() != Eigen::Success) return false;
  const ErrorCovariance root = llt.matrixL();
  offsets.col(0).setZero();
  offsets.middleCols<kErrorStateDimension>(1) = root;
  offsets.middleCols<kErrorStateDimension>(1 + kErrorStateDimension) = -root;
  return true;
}

void UnscentedKalmanFilter::predict(const ImuSample& sample, double dt) {
  if (dt <= 0.0) return;
  // The process model is linear in position, velocity, gravity and the wheel states (for a
  // fixed orientation, biases and gyro yaw scale). With those dimensions ordered last, the last
  // 11 columns of the Cholesky factor only touch them, so their 22 sigma points propagate exactly
  // by the linear map and only the other 20 + 1 go through propagate_state(): half the cost, the
  // same result.
  constexpr std::array<int, kErrorStateDimension> kOrder{3, 4, 5, 9, 10, 11, 12, 13, 14, 19, 0, 1, 2, 6, 7, 8, 15, 16, 17, 18, 20};
  constexpr int kNonlinear = 10;
  ErrorCovariance permuted;
  for (int i = 0; i < kErrorStateDimension; ++i) {
    for (int j = 0; j < kErrorStateDimension; ++j) permuted(i, j) = covariance_(kOrder[static_cast<size_t>(i)], kOrder[static_cast<size_t>(j)]);
  }
  const Eigen::LLT<ErrorCovariance> llt((kErrorStateDimension + lambda_) * (permuted + 1e-15 * ErrorCovariance::Identity()));
  if (llt.info() != Eigen::Success) {
    // Not positive definite (should not happen): propagate the mean alone, keep P plus Q.
    state_ = propagate_state(state_, body_motion(state_, sample, config_.imu_mounting), dt, config_.imu_mounting, nullptr);
    covariance_ += process_noise(config_.imu_noise, dt);
    return;
  }
  const ErrorCovariance root = llt.matrixL();
  const auto offset = [&root, &kOrder](int column) {
    ErrorVector o;
    for (int i = 0; i < kErrorStateDimension; ++i) o(kOrder[static_cast<size_t>(i)]) = root(i, column);
    return o;
  };
  const auto propagate = [&](const NavigationState& point) {
    return propagate_state(point, body_motion(point, sample, config_.imu_mounting), dt, config_.imu_mounting, nullptr);
  };
  const NavigationState center = propagate(state_);
  if (clone_) {
    ImuTransition transition;
    propagate_state(state_, body_motion(state_, sample, config_.imu_mounting), dt, config_.imu_mounting, &transition);
    multiply_by_transition_transpose(clone_->cross, transition);
  }
  Eigen::Matrix<double, kErrorStateDimension, kSigmaPoints> deltas;
  deltas.col(0).setZero();
  for (int column = 0; column < kErrorStateDimension; ++column) {
    const ErrorVector o = offset(column);
    for (int sign : {1, -1}) {
      const int index = sign > 0 ? 1 + column : 1 + kErrorStateDimension + column;
      if (column < kNonlinear) {
        deltas.col(index) = propagate(state_.plus(sign * o)).minus(center);
      } else {
        ErrorVector d = ErrorVector::Zero();
        const Eigen::Vector3d dp = sign * o.segment<3>(kPositionIndex);
        const Eigen::Vector3d dv = sign * o.segment<3>(kVelocityIndex);
        const Eigen::Vector3d dg = sign * o.segment<3>(kGravityIndex);
        d.segment<3>(kPositionIndex) = dp + dt * dv + 0.5 * dt * dt * dg;
        d.segment<3>(kVelocityIndex) = dv + dt * dg;
        d.segment<3>(kGravityIndex) = dg;
        d(kWheelScaleIndex) = sign * o(kWheelScaleIndex);
        d(kWheelHeadingDriftIndex) = sign * o(kWheelHeadingDriftIndex);
        deltas.col(index) = d;
      }
    }
  }
  ErrorVector mean = weight_ * deltas.rightCols<kSigmaPoints - 1>().rowwise().sum();
  deltas.colwise() -= mean;
  ErrorCovariance covariance = covariance_weight_0_ * deltas.col(0) * deltas.col(0).transpose();
  covariance.noalias() += weight_ * deltas.rightCols<kSigmaPoints - 1>() * deltas.rightCols<kSigmaPoints - 1>().transpose();
  state_ = center.plus(mean);
  covariance_ = covariance + process_noise(config_.imu_noise, dt);
  symmetrize(covariance_);
}

UpdateOutcome UnscentedKalmanFilter::update(const MeasurementModel& model, bool apply_gate) {
  using ResidualMatrix = Eigen::Matrix<double, Eigen::Dynamic, kSigmaPoints, 0, kMaxMeasurementDimension, kSigmaPoints>;
  using CrossCovariance = Eigen::Matrix<double, kErrorStateDimension, Eigen::Dynamic, 0, kErrorStateDimension, kMaxMeasurementDimension>;
  UpdateOutcome outcome;
  const int m = model.dimension();
  outcome.gate = gate_.threshold(m);
  Eigen::Matrix<double, kErrorStateDimension, kSigmaPoints> offsets;
  if (!sigma_offsets(offsets)) {
    outcome.status = UpdateStatus::kNumericalFailure;
    return outcome;
  }
  ResidualMatrix residuals(m, kSigmaPoints);
  MeasurementVector mean = MeasurementVector::Zero(m);
  for (int i = 0; i < kSigmaPoints; ++i) {
    residuals.col(i) = model.residual(i == 0 ? state_ : state_.plus(offsets.col(i)), nullptr);
    mean += (i == 0 ? mean_weight_0_ : weight_) * residuals.col(i);
  }
  outcome.innovation = mean;
  residuals.colwise() -= mean;
  MeasurementCovariance S = covariance_weight_0_ * residuals.col(0) * residuals.col(0).transpose() + model.covariance();
  S.noalias() += weight_ * residuals.rightCols<kSigmaPoints - 1>() * residuals.rightCols<kSigmaPoints - 1>().transpose();
  // offsets.col(0) is zero, so only the other sigma points contribute to P_xz.
  const CrossCovariance cross = -weight_ * offsets.rightCols<kSigmaPoints - 1>() * residuals.rightCols<kSigmaPoints - 1>().transpose();

  const Eigen::LLT<MeasurementCovariance> llt(S);
  if (!passes_gate(llt, mean, apply_gate, outcome)) return outcome;
  const CrossCovariance K = llt.solve(cross.transpose()).transpose();
  const NavigationState updated = state_.plus(K * mean);
  if (!updated.all_finite()) {
    outcome.status = UpdateStatus::kNumericalFailure;
    return outcome;
  }
  if (clone_) {
    using CloneGain = Eigen::Matrix<double, 6, Eigen::Dynamic, 0, 6, kMaxMeasurementDimension>;
    MeasurementJacobian H;
    model.residual(state_, &H);
    const CloneGain CHt = clone_->cross * H.transpose();  // Cov(clone, predicted measurement)
    const CloneGain clone_gain = llt.solve(CHt.transpose()).transpose();
    clone_->correction += clone_gain * mean;
    clone_->covariance -= clone_gain * CHt.transpose();
    clone_->cross -= CHt * K.transpose();
  }
  state_ = updated;
  covariance_ -= K * S * K.transpose();
  symmetrize(covariance_);
  return outcome;
}

}  // namespace hanzo::fusion::estimate
