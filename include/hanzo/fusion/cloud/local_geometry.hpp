#pragma once
// Local surface geometry from the k nearest neighbours of each point: the covariance of the
// neighbourhood (GICP's per-point distribution) and the surface normal.
//
// Covariances are regularized as in Generalized-ICP (Segal, Haehnel, Thrun 2009, Sec. III-B,
// "plane-to-plane"): the eigenvalues of the neighbourhood covariance are replaced by
// (epsilon, 1, 1) in its eigenbasis, so every point is a small disc in the local plane with
// unit extent (m^2) along it and epsilon across it. This makes the GICP cost independent of the
// sampling density and keeps each 3x3 matrix invertible. Normals are the eigenvector of the
// smallest eigenvalue, oriented toward the cloud's origin (the sensor for a scan).
//
// Points with fewer than 3 neighbours get an isotropic unit covariance and the normal toward
// the origin (they constrain registration like points of ICP).

#include "hanzo/fusion/cloud/kdtree.hpp"
#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::cloud {

struct LocalGeometryConfig {
  /// Neighbours per point, the point itself included (small_gicp uses 10, fast_gicp 20).
  int num_neighbors = 10;
  /// Variance across the local plane relative to the unit variance along it.
  double plane_epsilon = 1e-3;
  int num_threads = 1;
};

/// The neighbours each point's geometry came from: point i's are indices[i * k, (i + 1) * k),
/// closest first (i itself included), all within radii[i] (m) of it, and every other point of
/// the cloud at radii[i] or farther. k = min(num_neighbors, cloud size). Registration uses them
/// to update a correspondence without a tree search (registration_costs.hpp).
struct NeighbourLists {
  size_t k = 0;
  std::vector<uint32_t> indices;
  std::vector<float> radii;
};

/// Fills cloud.covariances and cloud.normals. `tree` must index exactly cloud.positions.
/// `neighbours`, when given, receives the neighbour lists.
void estimate_local_geometry(PointCloud& cloud, const KdTree& tree, const LocalGeometryConfig& config = {},
                             NeighbourLists* neighbours = nullptr);
/// The same, building the tree itself.
void estimate_local_geometry(PointCloud& cloud, const LocalGeometryConfig& config = {});

}  // namespace hanzo::fusion::cloud
