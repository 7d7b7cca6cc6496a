#pragma once
// Filter: the interface the three frontend filters (EKF, UKF, particle filter) share, so
// pipeline::Frontend drives any of them the same way:
//
//   reset(state, covariance)   start from a state and its error-state covariance
//   predict(sample, dt)        propagate by dt seconds with the IMU sample held constant
//   update(model)              fuse one measurement (chi-square gated)
//   state(), covariance()      current estimate (mean) and its error-state covariance (kErrorStateDimension square)
//   clone()                    a deep copy: snapshots for rolling back to fuse late messages
//
// Every update is gated: the squared Mahalanobis distance of the innovation,
// d^2 = r^T S^-1 r with S = H P H^T + R, is compared with the chi-square quantile of
// FilterConfig::gate_probability for the measurement's dimension; a measurement beyond it is
// rejected and the estimate does not change.

#include <array>
#include <cmath>
#include <memory>
#include <optional>
#include <string_view>

#include <Eigen/Cholesky>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"
#include "hanzo/fusion/estimate/map_frame.hpp"
#include "hanzo/fusion/estimate/measurement_model.hpp"
#include "hanzo/fusion/estimate/navigation_state.hpp"

namespace hanzo::fusion::estimate {

struct FilterConfig {
  ImuMounting imu_mounting;
  ImuNoise imu_noise;
  /// Probability mass of the chi-square gate; 0.999 rejects a correct measurement 1 time in
  /// 1000. 1.0 turns gating off. Must be in (0, 1].
  double gate_probability = 0.999;
};

enum class UpdateStatus {
  kApplied,           // the estimate moved
  kRejectedByGate,    // d^2 beyond the gate; estimate unchanged
  kNumericalFailure,  // S not positive definite, or the update produced non-finite numbers; unchanged
};
std::string_view to_string(UpdateStatus status);  // "applied", "gated", "numerical_failure"

struct UpdateOutcome {
  UpdateStatus status = UpdateStatus::kApplied;
  double mahalanobis_squared = 0.0;  // d^2 (normalized innovation squared, NIS)
  double gate = 0.0;                 // the threshold d^2 was compared with
  MeasurementVector innovation;      // residual at the prior estimate
};

/// A cloned pose (Filter::clone_pose()); errors ordered (position world, orientation body).
struct PoseClone {
  /// The smoothed clone is clone (+) correction: later measurements corrected it too.
  Eigen::Matrix<double, 6, 1> correction = Eigen::Matrix<double, 6, 1>::Zero();
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  /// Cov(clone error, current error state).
  Eigen::Matrix<double, 6, kErrorStateDimension> cross = Eigen::Matrix<double, 6, kErrorStateDimension>::Zero();
};

class Filter {
 public:
  virtual ~Filter() = default;
  virtual std::string_view name() const = 0;  // "ekf", "ukf", "particle"
  virtual void reset(const NavigationState& state, const ErrorCovariance& covariance) = 0;
  /// dt >= 0 seconds; sample in the IMU's axes (biases are removed with the estimated biases).
  virtual void predict(const ImuSample& sample, double dt) = 0;
  /// apply_gate = false fuses the measurement whatever its d^2 (used to recover when a sensor
  /// has disagreed with the estimate for so long that the estimate is the likelier culprit).
  virtual UpdateOutcome update(const MeasurementModel& model, bool apply_gate = true) = 0;
  virtual NavigationState state() const = 0;
  virtual ErrorCovariance covariance() const = 0;
  virtual std::unique_ptr<Filter> clone() const = 0;

  /// Moves the estimate rigidly in the world frame: p <- R_c p + t_c, R <- R_c R, v <- R_c v
  /// (a correction from the backend: T_c = T_optimized * T_estimated^-1 of a keyframe). The
  /// covariance is rotated accordingly; its size does not change.
  virtual void apply_world_transform(const SE3& T_correction) = 0;

  /// Stochastic cloning for keyframes: remember the current pose (position, orientation) and
  /// from now on track it as if it were part of the state: its correction by later updates,
  /// its covariance and its cross-covariance with the current error state. pose_clone() is
  /// nullopt before the first clone_pose() and after apply_world_transform(); relative
  /// covariances then leave the cross terms out.
  virtual void clone_pose() {}
  virtual std::optional<PoseClone> pose_clone() const { return std::nullopt; }

  /// Map frames (map_frame.hpp): a frame attached to the current body pose by T_body_map,
  /// estimated from now on with the state; returns its index (0, 1, ... in creation order), or
  /// none where the filter does not estimate map frames (its users then fix the frame in the
  /// world at the current estimate). reset() removes them; apply_world_transform() moves them
  /// with the world.
  virtual std::optional<int> add_map_frame(const SE3& /*T_body_map*/) { return std::nullopt; }
  /// The current estimate of map frame `frame`'s pose in the world; none for an unknown index.
  virtual std::optional<SE3> map_frame(int /*frame*/) const { return std::nullopt; }
  /// Fuses a pose in a map frame (gated as update()); a numerical failure for an unknown frame.
  virtual UpdateOutcome update_map_pose(const MapPoseModel& /*model*/, bool /*apply_gate*/ = true) {
    UpdateOutcome outcome;
    outcome.status = UpdateStatus::kNumericalFailure;
    return outcome;
  }
};

/// The gate every filter applies: d^2 = r^T S^-1 r from S's Cholesky factorization. Sets
/// outcome.mahalanobis_squared and, when the update must not be applied, outcome.status
/// (numerical failure when S is not positive definite or a number is not finite, gated beyond
/// outcome.gate when apply_gate). Returns true when the update may be applied.
template <typename Cholesky, typename Vector>
bool passes_gate(const Cholesky& s_cholesky, const Vector& innovation, bool apply_gate, UpdateOutcome& outcome) {
  if (s_cholesky.info() != Eigen::Success || !innovation.allFinite()) {
    outcome.status = UpdateStatus::kNumericalFailure;
    return false;
  }
  outcome.mahalanobis_squared = innovation.dot(s_cholesky.solve(innovation));
  if (!std::isfinite(outcome.mahalanobis_squared)) {
    outcome.status = UpdateStatus::kNumericalFailure;
    return false;
  }
  if (apply_gate && outcome.mahalanobis_squared > outcome.gate) {
    outcome.status = UpdateStatus::kRejectedByGate;
    return false;
  }
  return true;
}

/// apply_world_transform() for a state and its covariance (shared by the filters).
void transform_in_world(const SE3& T_correction, NavigationState& state, ErrorCovariance* covariance);

/// The chi-square gate for a measurement dimension (1..kMaxMeasurementDimension) at a
/// probability; +infinity when probability is 1.
class ChiSquareGate {
 public:
  explicit ChiSquareGate(double probability);
  double threshold(int dimension) const { return thresholds_[static_cast<size_t>(dimension)]; }

 private:
  std::array<double, kMaxMeasurementDimension + 1> thresholds_{};
};

}  // namespace hanzo::fusion::estimate
