#pragma once
// FactorGraph: a list of factors; its cost at some values is 1/2 sum ||r_k||^2 over the
// whitened residuals (chi2() returns the sum without the 1/2, as g2o reports it).

#include <vector>

#include "hanzo/fusion/graph/factor.hpp"

namespace hanzo::fusion::graph {

class FactorGraph {
 public:
  void add(FactorPointer factor) { factors_.push_back(std::move(factor)); }
  template <typename FactorType, typename... Arguments>
  void emplace(Arguments&&... arguments) {
    factors_.push_back(std::make_shared<FactorType>(std::forward<Arguments>(arguments)...));
  }
  /// emplace() with a robust kernel.
  template <typename FactorType, typename... Arguments>
  void emplace_robust(const RobustKernel& kernel, Arguments&&... arguments) {
    auto factor = std::make_shared<FactorType>(std::forward<Arguments>(arguments)...);
    factor->set_robust_kernel(kernel);
    factors_.push_back(std::move(factor));
  }
  const std::vector<FactorPointer>& factors() const { return factors_; }
  size_t size() const { return factors_.size(); }

  /// sum ||r_k||^2; fails when a factor's variable is missing from values.
  Result<double> chi2(const Values& values) const;
  /// sum rho_k(||r_k||^2) with each factor's robust kernel (what the optimizer minimizes, x2).
  Result<double> robust_chi2(const Values& values) const;

 private:
  std::vector<FactorPointer> factors_;
};

/// New factors and the initial values of the variables they introduce: one step of a growing
/// graph (IncrementalSmoother::update).
struct GraphUpdate {
  FactorGraph factors;
  Values values;
};

}  // namespace hanzo::fusion::graph
