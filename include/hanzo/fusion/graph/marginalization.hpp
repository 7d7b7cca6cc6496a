#pragma once
// Marginalization: variables taken out of a factor graph, their factors replaced by one Gaussian
// prior on the variables those factors also touch (the Markov blanket), so that a sliding
// window keeps what the removed measurements said about what remains (as OKVIS, VINS-Mono and
// Basalt do).
//
// The factors touching the marginalized variables m are linearized at the current values
// (whitened Jacobians J and residuals r; a robust kernel's weight rho'(||r||^2) applied to both,
// iteratively reweighted least squares), giving the Gauss-Newton system over (m, b):
//   H = sum J^T J,  g = sum J^T r.
// The Schur complement keeps b's part with m eliminated:
//   H_b = H_bb - H_bm H_mm^-1 H_mb,   g_b = g_b - H_bm H_mm^-1 g_m
// (H_mm^-1 as a pseudo-inverse: directions of m no factor constrains carry nothing). The prior is
// the quadratic 1/2 ||r0 + J0 d||^2 with J0^T J0 = H_b and J0^T r0 = g_b (J0 = S^1/2 V^T from
// H_b's eigen-decomposition, eigenvalues below relative_eigenvalue_floor of the largest dropped),
// d = x (-) x0 the variables' tangent offset from their values at marginalization.
//
// First-estimate Jacobians: the prior's J0 stays fixed at the linearization point x0 whatever the
// variables do later, so the information it holds is never re-linearized (re-linearizing it at
// other points would invent information along directions the removed measurements left
// unobserved, the inconsistency of Huang et al. 2008 / Dong-Si and Mourikis 2011); the offset d
// is exact (SE3: d = Log(x0^-1 x), whose Jacobian Jr^-1(d) multiplies J0).

#include <memory>
#include <set>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/graph/factor.hpp"

namespace hanzo::fusion::graph {

/// The Gaussian prior left by a marginalization: residual r0 + J0 (x (-) x0), whitened. (-) per
/// variable in its tangent: SE3 Log(x0^-1 x) (rho, phi), SE2 Log(x0^-1 x), vectors and biases
/// x - x0. Its dimension is the rank of the marginal information.
class LinearizedPriorFactor final : public Factor {
 public:
  /// keys and linearization point (one value per key); jacobian: rank x (sum of the tangent
  /// dimensions, in key order); residual: rank.
  LinearizedPriorFactor(std::vector<Key> keys, std::vector<Value> linearization_point, Eigen::MatrixXd jacobian, Eigen::VectorXd residual);
  int dimension() const override { return static_cast<int>(residual_.size()); }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

  const std::vector<Value>& linearization_point() const { return linearization_point_; }
  /// The information J0^T J0 over the keys' tangents.
  Eigen::MatrixXd information() const { return jacobian_.transpose() * jacobian_; }

 private:
  std::vector<Value> linearization_point_;
  std::vector<int> offsets_;  // of each key's tangent in the jacobian's columns
  Eigen::MatrixXd jacobian_;
  Eigen::VectorXd residual_;
};

struct MarginalizationConfig {
  /// Eigenvalues of the marginal information below this fraction of the largest are dropped
  /// (numerically unobserved directions: no information rather than noise).
  double relative_eigenvalue_floor = 1e-12;
};

struct Marginalization {
  /// The prior on the variables the factors share with the marginalized ones; null when they
  /// share none (the factors only constrained marginalized variables) or nothing is left.
  std::shared_ptr<LinearizedPriorFactor> prior;
  /// The Markov blanket (the prior's keys), sorted.
  std::vector<Key> kept;
};

/// Marginalizes `marginalized` out of `factors` (every factor that touches one of them; others
/// are allowed and end up in the prior as they are, linearized) at `values`. Fails when a factor's
/// variable has no value or a factor cannot be evaluated there.
Result<Marginalization> marginalize(const std::vector<FactorPointer>& factors, const Values& values, const std::set<Key>& marginalized,
                                    const MarginalizationConfig& config = {});

}  // namespace hanzo::fusion::graph
