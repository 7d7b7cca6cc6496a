#pragma once
// ErrorStateEkf: the error-state (multiplicative) extended Kalman filter (frontend.type: ekf).
// The nominal NavigationState is integrated by imu_propagation.hpp; the covariance of the error
// state is propagated with the block-sparse Phi P Phi^T + Q. An update computes
//   S = H P H^T + R,  K = P H^T S^-1,  dx = K r,  x <- x (+) dx,  P <- P - K S K^T
// then resets the error (Sola 2017, eq. 285-287: G = I - [dtheta/2]x in the orientation
// block). Filter contract and gating: filter.hpp.

#include "hanzo/fusion/estimate/filter.hpp"

namespace hanzo::fusion::estimate {

class ErrorStateEkf final : public Filter {
 public:
  explicit ErrorStateEkf(const FilterConfig& config);

  std::string_view name() const override { return "ekf"; }
  void reset(const NavigationState& state, const ErrorCovariance& covariance) override;
  void predict(const ImuSample& sample, double dt) override;
  UpdateOutcome update(const MeasurementModel& model, bool apply_gate = true) override;
  NavigationState state() const override { return state_; }
  ErrorCovariance covariance() const override { return covariance_; }
  std::unique_ptr<Filter> clone() const override { return std::make_unique<ErrorStateEkf>(*this); }
  void apply_world_transform(const SE3& T_correction) override;
  /// The augmented-state EKF's clone blocks without carrying the clone in the state: with
  /// C = Cov(clone, x) and Kc = C H^T S^-1: predict C <- C Phi^T; update correction += Kc r,
  /// covariance -= Kc S Kc^T, C <- C - Kc S K^T; error reset C <- C G^T (the clone's own
  /// reset is second order and left out).
  void clone_pose() override;
  std::optional<PoseClone> pose_clone() const override { return clone_; }

 private:
  template <int M>
  UpdateOutcome update_fixed(const MeasurementModel& model, bool apply_gate);

  FilterConfig config_;
  ChiSquareGate gate_;
  NavigationState state_;
  ErrorCovariance covariance_ = ErrorCovariance::Identity();
  std::optional<PoseClone> clone_;
};

}  // namespace hanzo::fusion::estimate
