#pragma once
// Initial poses for pose graphs whose own guess (chained odometry, drifted) would leave a
// local optimizer in a local minimum: the chordal relaxation of rotation averaging (Martinec &
// Pajdla, CVPR 2007; Carlone, Tron, Daniilidis, Dellaert, "Initialization techniques for 3D
// SLAM", ICRA 2015, section IV-C), then translations given those rotations.
//
//   1. Rotations: minimize sum_ij kappa_ij ||R_j - R_i R~_ij||_F^2 over unconstrained d x d
//      matrices with the anchor's rotation held. Written for each row r of the rotations,
//      z = row_r(R)^T, an edge is z_j - R~^T z_i (3D) or, for 2D rotations parametrized by
//      (cos, sin), (cos_j, sin_j) - R~ (cos_i, sin_i): linear least squares with one sparse
//      normal matrix for every row (Eigen's SimplicialLDLT, d or 1 right-hand sides).
//   2. Each solution projected to the nearest rotation (SVD, determinant +1; atan2 in 2D).
//   3. Translations: minimize sum_ij tau_ij ||t_j - t_i - R_i t~_ij||^2 with the rotations
//      fixed: a weighted graph Laplacian per coordinate.
// kappa and tau are SE-Sync's weights from the edges' information (g2o_io.hpp), so the result
// is the relaxation of the objective the chordal optimizer then minimizes.
//
// Anchors: the graph's fixed vertices keep their initial values (the first vertex when none is
// fixed, at its initial value or the identity). Fails when a vertex is not connected to an
// anchor by edges (the normal matrix is singular).

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/graph/g2o_io.hpp"

namespace hanzo::fusion::graph {

/// Values for every vertex of the graph (see the header comment).
Result<Values> chordal_initialization(const PoseGraph& graph);

}  // namespace hanzo::fusion::graph
