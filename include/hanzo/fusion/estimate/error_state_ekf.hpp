#pragma once
// ErrorStateEkf: the error-state (multiplicative) extended Kalman filter (frontend.type: ekf).
// The nominal NavigationState is integrated by imu_propagation.hpp; the covariance of the error
// state is propagated with the block-sparse Phi P Phi^T + Q. An update computes
//   S = H P H^T + R,  K = P H^T S^-1,  dx = K r,  x <- x (+) dx,  P <- P - K S K^T
// then resets the error (Sola 2017, eq. 285-287: G = I - [dtheta/2]x in the orientation
// block). Filter contract and gating: filter.hpp.

#include <vector>

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
  /// Map frames are anchors carried in the state (their nominal poses, their joint covariance
  /// and their cross-covariances with the state and the pose clone): every update corrects
  /// them, and they correct the state through map poses (update_map_pose).
  std::optional<int> add_map_frame(const SE3& T_body_map) override;
  std::optional<SE3> map_frame(int frame) const override;
  UpdateOutcome update_map_pose(const MapPoseModel& model, bool apply_gate = true) override;

 private:
  using AnchorCross = Eigen::Matrix<double, Eigen::Dynamic, kErrorStateDimension>;
  /// One update of the augmented state [x; anchors; clone] with measurement Jacobian
  /// [H, H_anchor (at map frame `frame`'s columns), 0]; H_anchor null: a model of the state alone.
  template <int M>
  UpdateOutcome update_augmented(const Eigen::Matrix<double, M, 1>& r, const Eigen::Matrix<double, M, kErrorStateDimension>& H,
                                 const Eigen::Matrix<double, M, 6>* H_anchor, int frame, const Eigen::Matrix<double, M, M>& R,
                                 bool apply_gate, UpdateOutcome outcome);
  template <int M>
  UpdateOutcome update_fixed(const MeasurementModel& model, bool apply_gate);

  FilterConfig config_;
  ChiSquareGate gate_;
  NavigationState state_;
  ErrorCovariance covariance_ = ErrorCovariance::Identity();
  std::optional<PoseClone> clone_;
  std::vector<MapFrameAnchor> anchors_;
  Eigen::MatrixXd anchor_covariance_;           ///< 6N x 6N
  AnchorCross anchor_cross_;                    ///< Cov(anchors, x), 6N x kErrorStateDimension
  Eigen::Matrix<double, 6, Eigen::Dynamic> clone_anchor_cross_;  ///< Cov(clone, anchors), 6 x 6N
};

}  // namespace hanzo::fusion::estimate
