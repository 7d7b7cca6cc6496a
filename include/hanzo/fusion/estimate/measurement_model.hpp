#pragma once
// MeasurementModel: what a sensor reading says about the state, in the form all three filters
// use (EKF: residual + Jacobian; UKF: residual at each sigma point; particle filter: residual
// -> likelihood).
//
//   residual(x) = z (-) h(x)            (vector difference, or a rotation-vector difference
//                                        for rotations), dimension() entries
//   jacobian    = d h(x (+) dx) / d dx  at dx = 0, so residual(x (+) dx) ~ residual(x) - H dx
//   covariance  = covariance of the measurement noise of z, in the residual's coordinates
//
// Every model's Jacobian is checked against numerical differentiation in
// tests/estimate/measurement_models_test.cpp. Models are small value types built per
// message; evaluating one never allocates (fixed maximum sizes below).

#include <string_view>

#include <Eigen/Core>

#include "hanzo/fusion/estimate/navigation_state.hpp"

namespace hanzo::fusion::estimate {

inline constexpr int kMaxMeasurementDimension = 6;

using MeasurementVector = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMaxMeasurementDimension, 1>;
using MeasurementJacobian =
    Eigen::Matrix<double, Eigen::Dynamic, kErrorStateDimension, Eigen::RowMajor, kMaxMeasurementDimension, kErrorStateDimension>;
using MeasurementCovariance =
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, kMaxMeasurementDimension, kMaxMeasurementDimension>;

class MeasurementModel {
 public:
  virtual ~MeasurementModel() = default;
  /// Short name used in counters and logs ("gnss_position", "wheel_odometry").
  virtual std::string_view name() const = 0;
  /// Number of residual entries, 1..kMaxMeasurementDimension.
  virtual int dimension() const = 0;
  /// z (-) h(state); fills jacobian (dimension() x 18) when given.
  virtual MeasurementVector residual(const NavigationState& state, MeasurementJacobian* jacobian) const = 0;
  /// Noise covariance of the residual (dimension() x dimension(), symmetric positive definite).
  virtual MeasurementCovariance covariance() const = 0;
};

}  // namespace hanzo::fusion::estimate
