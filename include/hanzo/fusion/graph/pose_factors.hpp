#pragma once
// Prior and between factors on SE2 and SE3 poses (odometry, loop closures, anchors).
//
//   Between: r = log(Z^-1 T_i^-1 T_j)       dr/dT_j = Jr^-1(r),  dr/dT_i = -Jr^-1(r) Ad(T_j^-1 T_i)
//   Prior:   r = log(Z^-1 T)                dr/dT = Jr^-1(r)
// then whitened by the noise model (tangent order of core/: translation first, then rotation).
// Z is "pose j in frame i" as g2o's EDGE_SE2 / EDGE_SE3:QUAT store it.

#include <cmath>
#include <type_traits>

#include "hanzo/fusion/graph/factor.hpp"

namespace hanzo::fusion::graph {

template <typename Pose>
class BetweenFactor final : public Factor {
 public:
  BetweenFactor(Key i, Key j, const Pose& measured, GaussianNoise noise)
      : Factor({i, j}), measured_inverse_(measured.inverse()), noise_(std::move(noise)) {}
  int dimension() const override { return noise_.dimension(); }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;
  Pose measured() const { return measured_inverse_.inverse(); }
  const GaussianNoise& noise() const { return noise_; }

  using Residual = typename Pose::Tangent;
  using PoseJacobian = typename Pose::Jacobian;
  /// The whitened residual at poses (Ti, Tj) and, when asked, its Jacobians: evaluate()'s work
  /// without the Values lookup and in fixed-size types (the batch optimizer's fast path).
  /// Requires dimension() == the tangent dimension.
  Residual whitened_error(const Pose& Ti, const Pose& Tj, PoseJacobian* jacobian_i, PoseJacobian* jacobian_j) const;

 private:
  Pose measured_inverse_;
  GaussianNoise noise_;
};

template <typename Pose>
class PriorFactor final : public Factor {
 public:
  PriorFactor(Key key, const Pose& prior, GaussianNoise noise) : Factor({key}), prior_inverse_(prior.inverse()), noise_(std::move(noise)) {}
  int dimension() const override { return noise_.dimension(); }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

 private:
  Pose prior_inverse_;
  GaussianNoise noise_;
};

/// The between factor of SE-Sync's objective (Rosen et al. 2019, eq. 7), whose global optimum
/// the SE-Sync papers publish: r = (sqrt(kappa) vec(R_j - R_i R~), sqrt(tau) (t_j - t_i - R_i t~)),
/// residual dimension d^2 + d. Chordal rotation distance instead of the geodesic one.
template <typename Pose>
class ChordalBetweenFactor final : public Factor {
 public:
  ChordalBetweenFactor(Key i, Key j, const Pose& measured, double kappa, double tau)
      : Factor({i, j}), measured_(measured), sqrt_kappa_(std::sqrt(kappa)), sqrt_tau_(std::sqrt(tau)) {}
  static constexpr int kSpace = std::is_same_v<Pose, SE2> ? 2 : 3;  ///< d
  int dimension() const override { return kSpace * kSpace + kSpace; }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

  using Residual = Eigen::Matrix<double, kSpace * kSpace + kSpace, 1>;
  using PoseJacobian = Eigen::Matrix<double, kSpace * kSpace + kSpace, Pose::Tangent::RowsAtCompileTime>;
  /// evaluate()'s work on poses, in fixed-size types (the batch optimizer's fast path).
  Residual whitened_error(const Pose& Ti, const Pose& Tj, PoseJacobian* jacobian_i, PoseJacobian* jacobian_j) const;

 private:
  Pose measured_;
  double sqrt_kappa_;
  double sqrt_tau_;
};

using BetweenFactorSE2 = BetweenFactor<SE2>;
using BetweenFactorSE3 = BetweenFactor<SE3>;
using PriorFactorSE2 = PriorFactor<SE2>;
using PriorFactorSE3 = PriorFactor<SE3>;

}  // namespace hanzo::fusion::graph
