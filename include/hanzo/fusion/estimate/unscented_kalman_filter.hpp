#pragma once
// UnscentedKalmanFilter (frontend.type: ukf): sigma points on the manifold, the same process
// and measurement models as the EKF, no Jacobians used.
//
// Sigma points (Wan & van der Merwe 2000, "The unscented Kalman filter for nonlinear
// estimation", eq. 15), n = 18 error-state dimensions, lambda = alpha^2 (n + kappa) - n:
//   chi_0 = x,  chi_{i} = x (+) col_i(sqrt((n + lambda) P)),  chi_{n+i} = x (+) -col_i(...)
//   weights Wm_0 = lambda / (n + lambda), Wc_0 = Wm_0 + (1 - alpha^2 + beta),
//           Wm_i = Wc_i = 1 / (2 (n + lambda)).
// Predict: every sigma point goes through propagate_state(); the new mean is
// chi'_0 (+) sum Wm_i (chi'_i (-) chi'_0) and the covariance the weighted spread plus Q.
// Update: residuals r_i = z (-) h(chi_i); innovation r = sum Wm_i r_i;
//   S = sum Wc_i (r_i - r)(r_i - r)^T + R,  P_xz = -sum Wc_i dx_i (r_i - r)^T,
//   K = P_xz S^-1,  x <- x (+) K r,  P <- P - K S K^T;  gated on r^T S^-1 r like the EKF.
// Cost: 2n + 1 = 37 state propagations per IMU sample.

#include "hanzo/fusion/estimate/filter.hpp"

namespace hanzo::fusion::estimate {

struct UkfConfig {
  double alpha = 1e-3;  // spread of the sigma points, (0, 1]
  double beta = 2.0;    // prior knowledge of the distribution (2 is optimal for Gaussians)
  double kappa = 0.0;   // secondary scaling, >= 3 - n is customary; n + kappa must be > 0
};

class UnscentedKalmanFilter final : public Filter {
 public:
  UnscentedKalmanFilter(const FilterConfig& config, const UkfConfig& ukf);

  std::string_view name() const override { return "ukf"; }
  void reset(const NavigationState& state, const ErrorCovariance& covariance) override;
  void predict(const ImuSample& sample, double dt) override;
  UpdateOutcome update(const MeasurementModel& model, bool apply_gate = true) override;
  NavigationState state() const override { return state_; }
  ErrorCovariance covariance() const override { return covariance_; }
  std::unique_ptr<Filter> clone() const override { return std::make_unique<UnscentedKalmanFilter>(*this); }
  void apply_world_transform(const SE3& T_correction) override;
  /// The clone is tracked with the EKF's linear recursion (transition blocks of the mean on
  /// predict, the models' Jacobians for the clone's gain on update): sigma points are not
  /// augmented with it.
  void clone_pose() override;
  std::optional<PoseClone> pose_clone() const override { return clone_; }

 private:
  static constexpr int kSigmaPoints = 2 * kErrorStateDimension + 1;
  /// The sigma-point offsets dx_i (columns; column 0 is zero). False when P is not positive definite.
  bool sigma_offsets(Eigen::Matrix<double, kErrorStateDimension, kSigmaPoints>& offsets) const;

  FilterConfig config_;
  ChiSquareGate gate_;
  double lambda_ = 0.0;
  double mean_weight_0_ = 0.0;
  double covariance_weight_0_ = 0.0;
  double weight_ = 0.0;
  NavigationState state_;
  ErrorCovariance covariance_ = ErrorCovariance::Identity();
  std::optional<PoseClone> clone_;
};

}  // namespace hanzo::fusion::estimate
