#include "hanzo/fusion/graph/optimality_certificate.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>

#include <Eigen/SparseCholesky>
#include <fmt/format.h>

#include "hanzo/fusion/graph/batch_optimizer.hpp"

namespace hanzo::fusion::graph {
namespace {

using SparseMatrix = Eigen::SparseMatrix<double>;
using Triplets = std::vector<Eigen::Triplet<double>>;

// Column layout of X = [t_1 .. t_n | R_1 .. R_n]: vertex k's translation is column k, its
// rotation columns n + k d .. n + k d + d - 1.
struct Layout {
  int dimension = 0;
  Eigen::Index vertices = 0;
  std::map<Key, Eigen::Index> index;
  Eigen::Index size() const { return vertices * (dimension + 1); }
  Eigen::Index translation(Key key) const { return index.at(key); }
  Eigen::Index rotation(Key key) const { return vertices + index.at(key) * dimension; }
};

// M = sum kappa A A^T + tau b b^T (header comment), from the rows each edge touches.
SparseMatrix data_matrix(const PoseGraph& graph, const Layout& layout) {
  const int d = layout.dimension;
  Triplets triplets;
  for (const PoseGraphEdge& edge : graph.edges) {
    const auto [kappa, tau] = se_sync_weights(edge, d);
    const Eigen::MatrixXd R_measured = pose_rotation(edge.measurement);
    const Eigen::VectorXd t_measured = pose_translation(edge.measurement);
    const Eigen::Index ri = layout.rotation(edge.from), rj = layout.rotation(edge.to);
    // kappa A A^T with A = e_j (x) I - e_i (x) R~: blocks (j,j) I, (i,i) R~ R~^T = I, (i,j) -R~, (j,i) -R~^T.
    for (int r = 0; r < d; ++r) {
      triplets.emplace_back(rj + r, rj + r, kappa);
      triplets.emplace_back(ri + r, ri + r, kappa);
      for (int c = 0; c < d; ++c) {
        triplets.emplace_back(ri + r, rj + c, -kappa * R_measured(r, c));
        triplets.emplace_back(rj + c, ri + r, -kappa * R_measured(r, c));
      }
    }
    // tau b b^T with b = e_tj - e_ti - (rotation rows of i) t~.
    std::vector<std::pair<Eigen::Index, double>> b = {{layout.translation(edge.to), 1.0}, {layout.translation(edge.from), -1.0}};
    for (int c = 0; c < d; ++c) b.emplace_back(ri + c, -t_measured(c));
    for (const auto& [row, row_value] : b) {
      for (const auto& [column, column_value] : b) triplets.emplace_back(row, column, tau * row_value * column_value);
    }
  }
  SparseMatrix M(layout.size(), layout.size());
  M.setFromTriplets(triplets.begin(), triplets.end());
  return M;
}

// X (d x n(d+1)) at `values`.
Eigen::MatrixXd pose_matrix(const Layout& layout, const Values& values) {
  Eigen::MatrixXd X = Eigen::MatrixXd::Zero(layout.dimension, layout.size());
  for (const auto& [key, index] : layout.index) {
    const Value& pose = values.all().at(key);
    X.col(layout.translation(key)) = pose_translation(pose);
    X.middleCols(layout.rotation(key), layout.dimension) = pose_rotation(pose);
  }
  return X;
}

// S = M - BlockDiag(Lambda), Lambda_i = sym(R_i^T (X M)_i) over the rotation blocks.
SparseMatrix certificate_matrix(const SparseMatrix& M, const Eigen::MatrixXd& X, const Layout& layout) {
  const int d = layout.dimension;
  const Eigen::MatrixXd XM = X * M;
  Triplets triplets;
  for (const auto& [key, index] : layout.index) {
    const Eigen::Index r = layout.rotation(key);
    const Eigen::MatrixXd product = X.middleCols(r, d).transpose() * XM.middleCols(r, d);
    const Eigen::MatrixXd lambda = 0.5 * (product + product.transpose());
    for (int row = 0; row < d; ++row) {
      for (int column = 0; column < d; ++column) triplets.emplace_back(r + row, r + column, -lambda(row, column));
    }
  }
  for (Eigen::Index i = 0; i < layout.size(); ++i) triplets.emplace_back(i, i, 0.0);  // a full diagonal for the shifts
  SparseMatrix S(layout.size(), layout.size());
  S.setFromTriplets(triplets.begin(), triplets.end());
  S += M;
  return S;
}

// Whether S + shift I is positive definite (its Cholesky factorization exists).
bool positive_definite(const SparseMatrix& S, double shift) {
  SparseMatrix shifted = S;
  for (Eigen::Index i = 0; i < S.rows(); ++i) shifted.coeffRef(i, i) += shift;
  const Eigen::SimplicialLLT<SparseMatrix> cholesky(shifted);
  return cholesky.info() == Eigen::Success;
}

// The shift at which S + shift I becomes positive definite, to 1 %, between `fails` (not
// positive definite) and `succeeds`: -lambda_min(S).
double definiteness_threshold(const SparseMatrix& S, double fails, double succeeds) {
  while (succeeds > 1.01 * fails) {
    const double middle = std::sqrt(fails * succeeds);
    (positive_definite(S, middle) ? succeeds : fails) = middle;
  }
  return succeeds;
}

// The smallest eigenvalue of S (see OptimalityCertificate::min_eigenvalue); `certified` tells
// whether S + tolerance I is positive definite.
double smallest_eigenvalue(const SparseMatrix& S, double tolerance, bool certified) {
  double gershgorin = 0.0;  // |lambda| <= the largest absolute row sum
  Eigen::VectorXd row_sums = Eigen::VectorXd::Zero(S.rows());
  for (Eigen::Index k = 0; k < S.outerSize(); ++k) {
    for (SparseMatrix::InnerIterator it(S, k); it; ++it) row_sums(it.row()) += std::abs(it.value());
  }
  gershgorin = row_sums.maxCoeff();
  const double floor = std::min(tolerance, 1e-12 * gershgorin);
  if (certified) {
    if (positive_definite(S, floor)) return 0.0;
    return -definiteness_threshold(S, floor, tolerance);
  }
  double fails = tolerance, succeeds = 10.0 * tolerance;
  while (!positive_definite(S, succeeds)) {
    fails = succeeds;
    succeeds *= 10.0;
    if (succeeds > 2.0 * gershgorin + 1.0) return -(2.0 * gershgorin + 1.0);  // cannot happen for a symmetric S
  }
  return -definiteness_threshold(S, fails, succeeds);
}

double rotation_angle(const Eigen::MatrixXd& Ra, const Eigen::MatrixXd& Rb) {
  const double trace = (Ra.transpose() * Rb).trace();
  const double cosine = (trace - static_cast<double>(Ra.rows() - 2)) / 2.0;  // 2D: 2 cos; 3D: 1 + 2 cos
  return std::acos(std::clamp(cosine, -1.0, 1.0));
}

}  // namespace

Result<OptimalityCertificate> certify_global_optimality(const PoseGraph& graph, const Values& solution,
                                                        const OptimalityCertificateConfig& config) {
  const auto start = std::chrono::steady_clock::now();
  if (graph.dimension != 2 && graph.dimension != 3) {
    return Error(fmt::format("optimality certificate: dimension must be 2 or 3, got {}", graph.dimension));
  }
  if (graph.vertices.empty()) return Error("optimality certificate: the graph has no vertex");
  Layout layout{graph.dimension, static_cast<Eigen::Index>(graph.vertices.size()), {}};
  Values given;
  for (Key key : graph.vertices) {
    const auto found = solution.all().find(key);
    if (found == solution.all().end()) return Error(fmt::format("optimality certificate: no pose for vertex {}", key_to_string(key)));
    layout.index.emplace(key, static_cast<Eigen::Index>(layout.index.size()));
    given.insert(key, found->second);
  }

  OptimalityCertificate certificate;
  HANZO_ASSIGN_OR_RETURN(certificate.objective_given, se_sync_objective(graph, given));
  certificate.refined = given;
  const auto finish = [&]() -> Result<OptimalityCertificate> {
    certificate.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return certificate;
  };
  if (graph.fixed.size() > 1) {
    certificate.objective_refined = certificate.objective_given;
    certificate.message = fmt::format("not certified: the graph fixes {} vertices (the certificate is for the problem with one gauge vertex)",
                                      graph.fixed.size());
    return finish();
  }

  // Refinement to a critical point of SE-Sync's objective.
  FactorGraph chordal;
  HANZO_ASSIGN_OR_RETURN(chordal, graph.factor_graph(PoseGraph::Objective::kChordal));
  BatchOptimizerConfig refinement;
  refinement.fixed = {graph.fixed.empty() ? graph.vertices.front() : graph.fixed.front()};
  refinement.max_iterations = config.refinement_iterations;
  refinement.function_tolerance = 1e-13;
  refinement.gradient_tolerance = 1e-13;
  refinement.parameter_tolerance = 1e-13;
  OptimizationSummary summary;
  HANZO_ASSIGN_OR_RETURN(summary, optimize(chordal, certificate.refined, refinement));
  certificate.refinement_iterations = summary.iterations;
  HANZO_ASSIGN_OR_RETURN(certificate.objective_refined, se_sync_objective(graph, certificate.refined));
  for (const auto& [key, index] : layout.index) {
    const Value& before = given.all().at(key);
    const Value& after = certificate.refined.all().at(key);
    certificate.max_translation_change =
        std::max(certificate.max_translation_change, (pose_translation(after) - pose_translation(before)).norm());
    certificate.max_rotation_change = std::max(certificate.max_rotation_change, rotation_angle(pose_rotation(before), pose_rotation(after)));
  }

  const SparseMatrix M = data_matrix(graph, layout);
  const SparseMatrix S = certificate_matrix(M, pose_matrix(layout, certificate.refined), layout);
  const double tolerance = std::max(config.eigenvalue_tolerance, config.relative_eigenvalue_tolerance * M.diagonal().maxCoeff());
  certificate.eigenvalue_tolerance = tolerance;
  certificate.certified = positive_definite(S, tolerance);
  certificate.min_eigenvalue = smallest_eigenvalue(S, tolerance, certificate.certified);
  certificate.message = certificate.certified
                            ? "certified globally optimal"
                            : fmt::format("not certified: the certificate matrix has eigenvalue {:.3g} < -{:.3g} (a local minimum or saddle, "
                                          "or the relaxation is not exact for this graph)",
                                          certificate.min_eigenvalue, tolerance);
  return finish();
}

}  // namespace hanzo::fusion::graph
