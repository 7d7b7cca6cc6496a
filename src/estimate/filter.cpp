#include "hanzo/fusion/estimate/filter.hpp"

#include <limits>

#include "hanzo/fusion/estimate/chi_square.hpp"

namespace hanzo::fusion::estimate {

std::string_view to_string(UpdateStatus status) {
  switch (status) {
    case UpdateStatus::kApplied: return "applied";
    case UpdateStatus::kRejectedByGate: return "gated";
    case UpdateStatus::kNumericalFailure: return "numerical_failure";
  }
  return "unknown";
}

ChiSquareGate::ChiSquareGate(double probability) {
  for (int dimension = 1; dimension <= kMaxMeasurementDimension; ++dimension) {
    thresholds_[static_cast<size_t>(dimension)] =
        probability >= 1.0 ? std::numeric_limits<double>::infinity() : chi_square_quantile(probability, dimension);
  }
}

void transform_in_world(const SE3& T_correction, NavigationState& state, ErrorCovariance* covariance) {
  const Eigen::Matrix3d R = T_correction.rotation().matrix();
  state.position = R * state.position + T_correction.translation();
  state.R_world_body = T_correction.rotation() * state.R_world_body;
  state.velocity = R * state.velocity;
  if (covariance == nullptr) return;
  // World-frame blocks (position, velocity) rotate; body-frame orientation errors, biases and
  // gravity (kept in the world frame, whose vertical does not move) stay.
  ErrorCovariance T = ErrorCovariance::Identity();
  T.block<3, 3>(kPositionIndex, kPositionIndex) = R;
  T.block<3, 3>(kVelocityIndex, kVelocityIndex) = R;
  *covariance = T * *covariance * T.transpose();
}

}  // namespace hanzo::fusion::estimate
