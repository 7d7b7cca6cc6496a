#pragma once
// Test helper: every Jacobian of a Factor against central differences of its whitened residual
// in each variable's tangent space (right perturbation, as the factors define them).

#include <gtest/gtest.h>

#include "hanzo/fusion/graph/factor.hpp"

namespace hanzo::fusion::graph {

inline Value perturbed(const Value& value, int k, double h) {
  if (const auto* se3 = std::get_if<SE3>(&value)) {
    SE3::Tangent delta = SE3::Tangent::Zero();
    delta(k) = h;
    return *se3 * SE3::exp(delta);
  }
  if (const auto* se2 = std::get_if<SE2>(&value)) {
    SE2::Tangent delta = SE2::Tangent::Zero();
    delta(k) = h;
    return *se2 * SE2::exp(delta);
  }
  if (const auto* bias = std::get_if<ImuBias>(&value)) {
    Eigen::Matrix<double, 6, 1> stacked = bias->vector();
    stacked(k) += h;
    return ImuBias::from_vector(stacked);
  }
  Eigen::Vector3d vector = std::get<Eigen::Vector3d>(value);
  vector(k) += h;
  return vector;
}

inline void expect_jacobians_match(const Factor& factor, const Values& values) {
  std::vector<Eigen::MatrixXd> analytic;
  ASSERT_TRUE(factor.evaluate(values, &analytic).ok());
  ASSERT_EQ(analytic.size(), factor.keys().size());
  constexpr double h = 1e-6;
  for (size_t v = 0; v < factor.keys().size(); ++v) {
    const Value& value = values.all().at(factor.keys()[v]);
    for (int k = 0; k < analytic[v].cols(); ++k) {
      Values plus = values, minus = values;
      plus.insert(factor.keys()[v], perturbed(value, k, h));
      minus.insert(factor.keys()[v], perturbed(value, k, -h));
      const Eigen::VectorXd numeric = (factor.evaluate(plus, nullptr).value() - factor.evaluate(minus, nullptr).value()) / (2 * h);
      EXPECT_LT((analytic[v].col(k) - numeric).cwiseAbs().maxCoeff(), 1e-6 * (1.0 + numeric.cwiseAbs().maxCoeff()))
          << key_to_string(factor.keys()[v]) << " column " << k;
    }
  }
}

}  // namespace hanzo::fusion::graph
