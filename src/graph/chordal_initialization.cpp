#include "hanzo/fusion/graph/chordal_initialization.hpp"

#include <algorithm>
#include <cmath>
#include <map>

#include <Eigen/SVD>
#include <Eigen/SparseCholesky>
#include <fmt/format.h>

namespace hanzo::fusion::graph {
namespace {

using SparseMatrix = Eigen::SparseMatrix<double>;
using Triplets = std::vector<Eigen::Triplet<double>>;

// Unknown blocks of `block` scalars per free vertex; anchors have no index.
struct Unknowns {
  std::map<Key, int> index;  // free vertex -> block index
  int count = 0;
};

// Adds weight * (z_j - M z_i) residual blocks to the normal equations H x = b, moving known
// (anchor) blocks to the right-hand side; z_known(key) gives an anchor's block (block x columns).
class NormalEquations {
 public:
  NormalEquations(const Unknowns& unknowns, int block, int columns)
      : unknowns_(unknowns), block_(block), b_(Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(unknowns.count) * block, columns)) {}

  void add(Key i, Key j, const Eigen::MatrixXd& M, double weight, const Eigen::MatrixXd& known_i, const Eigen::MatrixXd& known_j) {
    const auto free_i = unknowns_.index.find(i), free_j = unknowns_.index.find(j);
    const bool has_i = free_i != unknowns_.index.end(), has_j = free_j != unknowns_.index.end();
    const Eigen::MatrixXd MtM = M.transpose() * M;
    if (has_j) add_block(free_j->second, free_j->second, weight * Eigen::MatrixXd::Identity(block_, block_));
    if (has_i) add_block(free_i->second, free_i->second, weight * MtM);
    if (has_i && has_j) {
      add_block(free_i->second, free_j->second, -weight * M.transpose());
      add_block(free_j->second, free_i->second, -weight * M);
    }
    // Known parts: r = z_j - M z_i; H x = -J^T r_known.
    if (has_j && !has_i) b_.middleRows(static_cast<Eigen::Index>(free_j->second) * block_, block_) += weight * M * known_i;
    if (has_i && !has_j) b_.middleRows(static_cast<Eigen::Index>(free_i->second) * block_, block_) += weight * M.transpose() * known_j;
  }

  // The right-hand side for a residual with a constant part c: weight * (z_j - z_i - c).
  void add_constant(Key i, Key j, double weight, const Eigen::MatrixXd& constant) {
    if (const auto free_j = unknowns_.index.find(j); free_j != unknowns_.index.end()) {
      b_.middleRows(static_cast<Eigen::Index>(free_j->second) * block_, block_) += weight * constant;
    }
    if (const auto free_i = unknowns_.index.find(i); free_i != unknowns_.index.end()) {
      b_.middleRows(static_cast<Eigen::Index>(free_i->second) * block_, block_) -= weight * constant;
    }
  }

  Result<Eigen::MatrixXd> solve(const char* what) {
    const auto size = static_cast<Eigen::Index>(unknowns_.count) * block_;
    SparseMatrix H(size, size);
    H.setFromTriplets(triplets_.begin(), triplets_.end());
    Eigen::SimplicialLDLT<SparseMatrix> solver(H);
    if (solver.info() != Eigen::Success) {
      return Error(fmt::format("chordal initialization: the {} system is singular (is every vertex connected to an anchor?)", what));
    }
    Eigen::MatrixXd x = solver.solve(b_);
    if (solver.info() != Eigen::Success || !x.allFinite()) return Error(fmt::format("chordal initialization: the {} solve failed", what));
    return x;
  }

 private:
  void add_block(int row, int column, const Eigen::MatrixXd& value) {
    for (int r = 0; r < block_; ++r) {
      for (int c = 0; c < block_; ++c) {
        if (value(r, c) != 0.0) triplets_.emplace_back(row * block_ + r, column * block_ + c, value(r, c));
      }
    }
  }

  const Unknowns& unknowns_;
  int block_;
  Triplets triplets_;
  Eigen::MatrixXd b_;
};

// Nearest rotation (Frobenius) to a d x d matrix.
Eigen::MatrixXd project_to_rotation(const Eigen::MatrixXd& matrix) {
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(matrix, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::MatrixXd correction = Eigen::MatrixXd::Identity(matrix.rows(), matrix.cols());
  correction(matrix.rows() - 1, matrix.cols() - 1) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  return svd.matrixU() * correction * svd.matrixV().transpose();
}

}  // namespace

Result<Values> chordal_initialization(const PoseGraph& graph) {
  const int d = graph.dimension;
  if (d != 2 && d != 3) return Error(fmt::format("chordal initialization: dimension must be 2 or 3, got {}", d));
  if (graph.vertices.empty()) return Error("chordal initialization: the graph has no vertex");
  std::vector<Key> anchors = graph.fixed.empty() ? std::vector<Key>{graph.vertices.front()} : graph.fixed;
  std::map<Key, Value> anchor_poses;
  for (Key anchor : anchors) {
    const auto found = graph.initial.all().find(anchor);
    anchor_poses[anchor] = found != graph.initial.all().end() ? found->second : (d == 2 ? Value(SE2()) : Value(SE3()));
  }
  Unknowns unknowns;
  for (Key vertex : graph.vertices) {
    if (anchor_poses.count(vertex) == 0 && unknowns.index.count(vertex) == 0) unknowns.index[vertex] = unknowns.count++;
  }

  for (const PoseGraphEdge& edge : graph.edges) {
    for (Key key : {edge.from, edge.to}) {
      if (anchor_poses.count(key) == 0 && unknowns.index.count(key) == 0) {
        return Error(fmt::format("chordal initialization: edge {} - {}: {} is not a vertex", key_to_string(edge.from),
                                 key_to_string(edge.to), key_to_string(key)));
      }
    }
  }

  // 1-2. Rotations, as rows (3D: z = row_r(R)^T, d right-hand sides) or (cos, sin) (2D).
  const int rotation_columns = d == 3 ? 3 : 1;
  auto rotation_unknown = [&](const Eigen::MatrixXd& R) -> Eigen::MatrixXd {
    if (d == 3) return R.transpose();          // column r = row r of R
    return Eigen::Vector2d(R(0, 0), R(1, 0));  // (cos, sin)
  };
  NormalEquations rotations(unknowns, d, rotation_columns);
  std::vector<SeSyncWeights> weights;
  for (const PoseGraphEdge& edge : graph.edges) {
    weights.push_back(se_sync_weights(edge, d));
    const Eigen::MatrixXd measured = pose_rotation(edge.measurement);
    const Eigen::MatrixXd M = d == 3 ? Eigen::MatrixXd(measured.transpose()) : measured;
    const auto known = [&](Key key) {
      const auto anchor = anchor_poses.find(key);
      return anchor != anchor_poses.end() ? rotation_unknown(pose_rotation(anchor->second)) : Eigen::MatrixXd::Zero(d, rotation_columns);
    };
    rotations.add(edge.from, edge.to, M, weights.back().kappa, known(edge.from), known(edge.to));
  }
  Eigen::MatrixXd rotation_solution;
  HANZO_ASSIGN_OR_RETURN(rotation_solution, rotations.solve("rotation"));
  std::map<Key, Eigen::MatrixXd> rotation;
  for (const auto& [key, pose] : anchor_poses) rotation[key] = pose_rotation(pose);
  for (const auto& [key, index] : unknowns.index) {
    const Eigen::MatrixXd z = rotation_solution.middleRows(static_cast<Eigen::Index>(index) * d, d);
    if (d == 3) {
      rotation[key] = project_to_rotation(z.transpose());
    } else {
      rotation[key] = SE2(std::atan2(z(1, 0), z(0, 0)), Eigen::Vector2d::Zero()).rotation_matrix();
    }
  }

  // 3. Translations with the rotations fixed: t_j - t_i = R_i t~ per coordinate.
  NormalEquations translations(unknowns, 1, d);
  for (size_t e = 0; e < graph.edges.size(); ++e) {
    const PoseGraphEdge& edge = graph.edges[e];
    const auto known = [&](Key key) -> Eigen::MatrixXd {
      const auto anchor = anchor_poses.find(key);
      return anchor != anchor_poses.end() ? Eigen::MatrixXd(pose_translation(anchor->second).transpose()) : Eigen::MatrixXd::Zero(1, d);
    };
    const Eigen::MatrixXd identity = Eigen::MatrixXd::Identity(1, 1);
    translations.add(edge.from, edge.to, identity, weights[e].tau, known(edge.from), known(edge.to));
    translations.add_constant(edge.from, edge.to, weights[e].tau, (rotation.at(edge.from) * pose_translation(edge.measurement)).transpose());
  }
  Eigen::MatrixXd translation_solution;
  HANZO_ASSIGN_OR_RETURN(translation_solution, translations.solve("translation"));

  Values values;
  for (const auto& [key, pose] : anchor_poses) values.insert(key, pose);
  for (const auto& [key, index] : unknowns.index) {
    const Eigen::VectorXd t = translation_solution.row(index).transpose();
    if (d == 3) {
      values.insert(key, SE3(SO3::from_matrix(rotation.at(key)), Eigen::Vector3d(t)));
    } else {
      values.insert(key, SE2(std::atan2(rotation.at(key)(1, 0), rotation.at(key)(0, 0)), Eigen::Vector2d(t)));
    }
  }
  return values;
}

}  // namespace hanzo::fusion::graph
