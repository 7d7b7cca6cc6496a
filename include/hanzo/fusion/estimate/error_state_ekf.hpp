#pragma once
// ErrorStateEkf: the error-state (multiplicative) extended Kalman filter (frontend.type: ekf).
// The nominal NavigationState is integrated by imu_propagation.hpp; the 18x18 covariance of
// the error state is propagated with the block-sparse Phi P Phi^T + Q. An update computes
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

 private:
  FilterConfig config_;
  ChiSquareGate gate_;
  NavigationState state_;
  ErrorCovariance covariance_ = ErrorCovariance::Identity();
};

}  // namespace hanzo::fusion::estimate
