#pragma once
// Batch optimization of a FactorGraph with Ceres (Levenberg-Marquardt or dogleg, sparse
// Cholesky of the normal equations). Poses are Ceres parameter blocks with their own
// manifolds (SE2: x, y, theta; SE3: translation + quaternion x, y, z, w) updated by
// T <- T Exp(d), so the factors' tangent-space Jacobians are used as they are.

#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/graph/factor_graph.hpp"

namespace hanzo::fusion::graph {

struct BatchOptimizerConfig {
  enum class Method { kLevenbergMarquardt, kDogleg };
  Method method = Method::kLevenbergMarquardt;
  int max_iterations = 100;
  /// Relative cost decrease that ends the run (Ceres' default). 1e-6 leaves the standard pose
  /// graphs within 1e-5 of their optimum at half the iterations of 1e-8 (sphere2500 from the
  /// chordal initialization: 16 instead of 30).
  double function_tolerance = 1e-6;
  /// Levenberg-Marquardt's first trust region radius (the inverse of its first damping).
  /// 1e8 starts close to Gauss-Newton, which suits pose graphs that start from odometry or a
  /// chordal initialization: measured against Ceres' default 1e4, parking-garage 22 -> 17
  /// iterations, sphere2500 (chordal start) 16 -> 13, city10000 (chordal) 10 -> 4, same optima.
  /// A step that fails shrinks the radius fast (halved, then quartered, ...), so a poor start
  /// costs a few rejected steps.
  double initial_trust_region_radius = 1e8;
  double gradient_tolerance = 1e-12;
  double parameter_tolerance = 1e-12;
  int num_threads = 1;
  /// Variables held constant (the gauge: usually the first pose).
  std::vector<Key> fixed;
};

struct OptimizationSummary {
  double initial_chi2 = 0.0;  // sum of squared whitened residuals (through the robust kernels)
  double final_chi2 = 0.0;
  int iterations = 0;
  double seconds = 0.0;
  bool converged = false;
  std::string message;        // Ceres' termination message
};

/// Optimizes `values` in place. Fails when a factor's variable is missing from values or a
/// fixed key is unknown.
Result<OptimizationSummary> optimize(const FactorGraph& graph, Values& values, const BatchOptimizerConfig& config = {});

/// Marginal covariances of `keys` at `values` (usually the optimum), each in its variable's
/// tangent space (right perturbation; SE3: translation then rotation), from the Gauss-Newton
/// information of the whole graph with config.fixed held constant (Ceres' Covariance,
/// sparse). Fails when the information is rank deficient (no gauge fixed, unconstrained
/// variables) or a key is unknown.
Result<std::vector<Eigen::MatrixXd>> marginal_covariances(const FactorGraph& graph, const Values& values, const std::vector<Key>& keys,
                                                          const BatchOptimizerConfig& config = {});

}  // namespace hanzo::fusion::graph
