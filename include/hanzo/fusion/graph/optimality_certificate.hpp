#pragma once
// A global-optimality certificate for pose graphs: SE-Sync's verification (Rosen, Carlone,
// Bandeira, Leonard, "SE-Sync: a certifiably correct algorithm for synchronization over the
// special Euclidean group", IJRR 2019, Theorem 7 and section 4.1), in the explicit form that
// keeps the translations as variables.
//
// The problem certified is SE-Sync's objective (se_sync_objective() in g2o_io.hpp)
//   F(X) = sum_ij kappa_ij ||R_j - R_i R~_ij||_F^2 + tau_ij ||t_j - t_i - R_i t~_ij||^2
// with X = [t_1 .. t_n | R_1 .. R_n] (d x n(d+1)), written F(X) = tr(X M X^T) with the sparse
// symmetric data matrix M = sum_ij kappa_ij A_ij A_ij^T + tau_ij b_ij b_ij^T, where
// X A_ij = R_j - R_i R~_ij and X b_ij = t_j - t_i - R_i t~_ij.
// At a first-order critical point X the Lagrange multipliers of R_i^T R_i = I are
// Lambda_i = sym(R_i^T (X M)_i) (the rotation columns of block i; zero for translations), and
//   S = M - BlockDiag(Lambda)   (the certificate matrix).
// S X^T = 0 at a critical point; if moreover S is positive semidefinite, X is a global minimum
// of F over all poses (the semidefinite relaxation is exact). Numerically: certified when
// lambda_min(S) >= -tolerance, tested by a sparse Cholesky factorization of S + tolerance I (it
// succeeds exactly when that matrix is positive definite, up to rounding of the order
// 1e-16 ||S||). The tolerance scales with the problem: the eigenvalues of S scale with the
// measurements' weights, and so does the error a critical point found to double precision
// leaves in them, so
//   tolerance = max(eigenvalue_tolerance, relative_eigenvalue_tolerance * max_k M_kk).
// with relative_eigenvalue_tolerance 1e-7 (SE-Sync itself accepts lambda_min >= -1e-4 .. -1e-3 on
// benchmarks whose max M_kk is 1e2 .. 1e5; a local minimum's is of the order of its weights:
// -89 for the Intel graph trapped by scrambled headings).
//
// The solution to certify is first refined on F itself (Levenberg-Marquardt with tight
// tolerances, only the gauge vertex held), because the multipliers are those of an exact
// critical point: a solution of a different objective (g2o's geodesic errors) or a loosely
// converged one is a few millimetres away from the critical point of F, and its certificate
// matrix would be indefinite by the size of the residual gradient.
//
// A graph with more than one fixed vertex is a different (constrained) problem; it is reported
// as not certified with that reason. Failures (missing poses, dimension other than 2 or 3) are
// errors.

#include <string>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/graph/g2o_io.hpp"

namespace hanzo::fusion::graph {

struct OptimalityCertificateConfig {
  /// Certified when the certificate matrix's smallest eigenvalue is >= -tolerance, tolerance the
  /// larger of eigenvalue_tolerance (units of the objective) and relative_eigenvalue_tolerance
  /// times the largest diagonal entry of the data matrix M (header comment).
  double eigenvalue_tolerance = 1e-6;
  double relative_eigenvalue_tolerance = 1e-7;
  /// Levenberg-Marquardt iterations of the refinement on SE-Sync's objective.
  int refinement_iterations = 50;
};

struct OptimalityCertificate {
  bool certified = false;
  /// Smallest eigenvalue of S, to about 1 % (or 1e-12 ||S||, below which it is reported as 0).
  double min_eigenvalue = 0.0;
  /// The tolerance the test used (config comment).
  double eigenvalue_tolerance = 0.0;
  /// SE-Sync's objective at the given solution and at the refined (certified) one.
  double objective_given = 0.0;
  double objective_refined = 0.0;
  /// Largest distance between a pose of the given solution and the refined one (m, and rad).
  double max_translation_change = 0.0;
  double max_rotation_change = 0.0;
  int refinement_iterations = 0;
  double seconds = 0.0;
  std::string message;  ///< why not certified, or "certified globally optimal"
  Values refined;       ///< the refined solution, the one the certificate is about
};

/// Refines `solution` on SE-Sync's objective and tests its certificate (header comment).
/// Fails when a vertex has no pose in `solution` or the dimension is not 2 or 3.
Result<OptimalityCertificate> certify_global_optimality(const PoseGraph& graph, const Values& solution,
                                                        const OptimalityCertificateConfig& config = {});

}  // namespace hanzo::fusion::graph
