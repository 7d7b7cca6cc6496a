#pragma once
// Factor: one term of a factor graph's cost, 1/2 ||r(x)||^2 with r the WHITENED residual
// (noise_model.hpp). Every factor gives r and its Jacobians with respect to each of its
// variables in the variable's tangent space (right perturbation x (+) d = x Exp(d), as in
// core/so3.hpp); tests check every Jacobian against numerical differentiation.

#include <memory>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/graph/values.hpp"

namespace hanzo::fusion::graph {

/// Gaussian noise as the upper-triangular square root U of the information matrix
/// (U^T U = information), so the whitened residual is U r and ||U r||^2 = r^T information r.
class GaussianNoise {
 public:
  /// Fails unless information is symmetric positive definite and finite.
  static Result<GaussianNoise> from_information(const Eigen::MatrixXd& information);
  static Result<GaussianNoise> from_covariance(const Eigen::MatrixXd& covariance);
  /// Diagonal covariance with these standard deviations (all > 0).
  static Result<GaussianNoise> from_sigmas(const Eigen::VectorXd& sigmas);

  const Eigen::MatrixXd& sqrt_information() const { return sqrt_information_; }
  Eigen::MatrixXd information() const { return sqrt_information_.transpose() * sqrt_information_; }
  int dimension() const { return static_cast<int>(sqrt_information_.rows()); }

 private:
  Eigen::MatrixXd sqrt_information_;
};

/// A robust kernel on a factor's squared whitened residual s = ||r||^2 (loop closures that may
/// be wrong). Huber and Cauchy with their usual parameter (in residual units, default 1);
/// DCS, dynamic covariance scaling (Agarwal et al., ICRA 2013): the residual is scaled by
/// min(1, 2 phi / (phi + s)), so a wrong loop closure switches itself off (parameter phi).
struct RobustKernel {
  enum class Type { kNone, kHuber, kCauchy, kDcs };
  Type type = Type::kNone;
  double parameter = 1.0;  // > 0
};

class Factor {
 public:
  explicit Factor(std::vector<Key> keys) : keys_(std::move(keys)) {}
  virtual ~Factor() = default;
  const std::vector<Key>& keys() const { return keys_; }
  /// Residual dimension.
  virtual int dimension() const = 0;
  /// Whitened residual at `values`; jacobians (when given) receive one matrix per key,
  /// dimension() x tangent dimension of that variable. Fails when a variable is missing or has
  /// the wrong type.
  virtual Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const = 0;

  void set_robust_kernel(const RobustKernel& kernel) { robust_kernel_ = kernel; }
  const RobustKernel& robust_kernel() const { return robust_kernel_; }
  /// The factor's cost contribution rho(||r||^2) (||r||^2 without a kernel).
  double robust_cost(double squared_residual) const;

 private:
  std::vector<Key> keys_;
  RobustKernel robust_kernel_;
};

using FactorPointer = std::shared_ptr<const Factor>;

}  // namespace hanzo::fusion::graph
