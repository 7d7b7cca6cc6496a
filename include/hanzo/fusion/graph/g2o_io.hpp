#pragma once
// Pose graphs in g2o's text format (the format of the SE-Sync / g2o benchmark files), and in
// TORO's (`.graph`, the older format of the same benchmarks; GTSAM reads both):
//   VERTEX_SE2 id x y theta
//   EDGE_SE2 i j dx dy dtheta  I11 I12 I13 I22 I23 I33          (information upper triangle)
//   VERTEX_SE3:QUAT id x y z qx qy qz qw
//   EDGE_SE3:QUAT i j dx dy dz dqx dqy dqz dqw  + 21 information entries (upper triangle,
//                                                 order x y z | quaternion x y z)
// TORO records (read by the same parser, written by write_toro()):
//   VERTEX2 id x y theta
//   EDGE2 i j dx dy dtheta  Ixx Ixy Iyy Itt Ixt Iyt
//   VERTEX3 id x y z roll pitch yaw                   R = Rz(yaw) Ry(pitch) Rx(roll)
//   EDGE3 i j dx dy dz roll pitch yaw  + 21 information entries (upper triangle, order
//                                        x y z roll pitch yaw)
//   EQUIV i j                          vertex equivalences: not supported, skipped and counted
// TORO's 3D information (roll, pitch, yaw ~ the rotation vector) is stored converted to g2o's
// convention (below), so both formats give the same factors.
// An edge measures pose j in frame i. Vertex id n becomes key X(n). Vertices without a VERTEX
// line are initialized by chaining edges from known ones. `FIX id` lines mark fixed vertices.
//
// g2o's 3D information is over the quaternion's vector part, which is half the rotation
// vector; the between factors here use the rotation vector, so their information is
// diag(I, I/2) * info * diag(I, I/2) (what GTSAM does too).
//
// Errors name the file and line: unknown tags, wrong field counts, non-finite numbers,
// quaternions off unit norm by more than 1e-3, 2D and 3D mixed, vertices no edge connects to a
// known one. An information matrix that is not positive definite (semi-definite with a zero
// block, or indefinite, as real benchmark files have) is not an error: the geodesic factors use
// the nearest positive definite matrix (eigenvalues raised to at least 1e-6 of the largest) and
// a warning naming file and line goes into PoseGraph::warnings (and the log). SE-Sync's
// objective takes only the translation and rotation blocks of the file's matrix (SE-Sync's
// read_g2o), so it is computed from the file's numbers whenever those blocks are positive
// definite, whatever the coupling between them; only where a block itself is not (a zero row)
// do its weights come from the repaired matrix, with a warning of its own kind.

#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/graph/factor_graph.hpp"

namespace hanzo::fusion::graph {

struct PoseGraphEdge {
  Key from = 0;
  Key to = 0;
  Value measurement;               // SE2 or SE3: pose `to` in frame `from`
  Eigen::MatrixXd information;     // file_information, or the nearest positive definite matrix
  Eigen::MatrixXd file_information;  // as in the file (g2o's error coordinates; TORO's converted); empty: `information`
};

/// One thing the reader repaired or could not take as written. `kind` groups warnings of the
/// same cause (a large benchmark file can have thousands): "information_repaired" (the full
/// matrix is not positive definite; the geodesic factors use the nearest one),
/// "se_sync_weights_from_repaired" (a translation or rotation block of the file's matrix is not
/// positive definite, so SE-Sync's weights come from the repaired matrix).
struct PoseGraphWarning {
  std::string kind;
  std::string text;  ///< "file:line: TAG: what"
};

struct PoseGraph {
  int dimension = 2;               // 2 or 3
  Values initial;                  // VERTEX lines, then chained edges for the missing ones
  std::vector<Key> vertices;       // in file order (chained ones after)
  std::vector<PoseGraphEdge> edges;
  std::vector<Key> fixed;          // FIX lines; the first vertex when there are none
  int skipped_equivalences = 0;    // TORO EQUIV lines (not supported)
  std::vector<PoseGraphWarning> warnings;  // per edge, in file order

  /// What the optimizer minimizes: g2o's (geodesic) between factors, or SE-Sync's objective
  /// (chordal rotation distance), whose global optima the SE-Sync papers publish.
  enum class Objective { kGeodesic, kChordal };
  /// One between factor per edge: geodesic with noise from the information (converted for 3D,
  /// see above), or chordal with SE-Sync's kappa and tau (se_sync_objective()).
  Result<FactorGraph> factor_graph(Objective objective = Objective::kGeodesic) const;
  /// The graph as it grows, pose by pose, for an incremental smoother: vertices in the order
  /// the edges (file order) first reach them, one update each, holding the vertex and every
  /// edge whose later vertex it is (odometry and loop closures back to earlier poses). A new
  /// vertex starts at its neighbour composed with the edge (odometry), not at its VERTEX line;
  /// the first vertex (or the first fixed one) starts at its VERTEX value, in an update of its
  /// own. Fails when an edge joins two vertices that no earlier edge reached.
  Result<std::vector<GraphUpdate>> incremental_updates(Objective objective = Objective::kGeodesic) const;
};

Result<PoseGraph> read_g2o(const std::string& path);
/// source_name stands in for the file name in error messages.
Result<PoseGraph> parse_g2o(const std::string& text, const std::string& source_name);
/// The graph's vertices at `values` and its edges, in g2o's format; numbers in shortest
/// round-trip form, so reading the file back gives the same graph. Written atomically.
Status write_g2o(const std::string& path, const PoseGraph& graph, const Values& values);

/// The same in TORO's format (VERTEX2/EDGE2 or VERTEX3/EDGE3; FIX lines are not part of it).
Status write_toro(const std::string& path, const PoseGraph& graph, const Values& values);

/// The rotation matrix (d x d) and the translation (d) of an SE2 or SE3 pose value.
Eigen::MatrixXd pose_rotation(const Value& pose);
Eigen::VectorXd pose_translation(const Value& pose);

/// g2o's chi2: sum e^T info e with g2o's errors (SE2: (x, y, wrapped theta) of Z^-1 Ti^-1 Tj;
/// SE3: translation and quaternion vector part, w >= 0), info the (repaired) information the
/// geodesic factors use.
Result<double> g2o_chi2(const PoseGraph& graph, const Values& values);
/// SE-Sync's weights of one edge: tau = d / trace(info_tt^-1), kappa = info_thetatheta (2D) or
/// 3 / (2 trace(info_RR^-1)) (3D); d the graph's dimension; info the file's information where
/// its blocks are positive definite, else the repaired one (header comment).
struct SeSyncWeights {
  double kappa = 0.0;  ///< rotation
  double tau = 0.0;    ///< translation
};
SeSyncWeights se_sync_weights(const PoseGraphEdge& edge, int dimension);

/// Warnings of one kind: how many, and the first few lines.
struct WarningGroup {
  std::string kind;
  std::size_t count = 0;
  std::vector<std::string> first;
};
std::vector<WarningGroup> group_warnings(const std::vector<PoseGraphWarning>& warnings, std::size_t examples = 3);

/// SE-Sync's objective (Rosen et al. 2019): sum kappa ||R_j - R_i R~||_F^2 + tau ||t_j - t_i - R_i t~||^2
/// with tau = d / trace(info_tt^-1), kappa = info_thetatheta (2D) or 3 / (2 trace(info_RR^-1)) (3D).
Result<double> se_sync_objective(const PoseGraph& graph, const Values& values);

}  // namespace hanzo::fusion::graph
