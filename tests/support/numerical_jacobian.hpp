#pragma once
// Central finite differences for checking analytic Jacobians.

#include <Eigen/Core>

namespace hanzo::fusion::testing {

/// d g(delta) / d delta at delta = 0 for g: R^N -> R^M, by central differences with step h.
template <int N, int M, typename Function>
Eigen::Matrix<double, M, N> numerical_jacobian(Function g, double h = 1e-6) {
  Eigen::Matrix<double, M, N> jacobian;
  for (int i = 0; i < N; ++i) {
    Eigen::Matrix<double, N, 1> delta = Eigen::Matrix<double, N, 1>::Zero();
    delta[i] = h;
    jacobian.col(i) = (g(delta) - g(-delta)) / (2.0 * h);
  }
  return jacobian;
}

}  // namespace hanzo::fusion::testing
