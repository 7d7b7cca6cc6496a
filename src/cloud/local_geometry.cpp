#include "hanzo/fusion/cloud/local_geometry.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

#include <Eigen/Eigenvalues>

#include "hanzo/fusion/cloud/parallel.hpp"

namespace hanzo::fusion::cloud {
namespace {

Eigen::Vector3f toward_origin(const Eigen::Vector3f& normal, const Eigen::Vector3f& position) {
  return normal.dot(position) > 0.0f ? Eigen::Vector3f(-normal) : normal;
}

}  // namespace

void estimate_local_geometry(PointCloud& cloud, const KdTree& tree, const LocalGeometryConfig& config, NeighbourLists* neighbours) {
  assert(tree.size() == cloud.size());
  assert(config.num_neighbors >= 1);
  const size_t k = static_cast<size_t>(config.num_neighbors);
  cloud.covariances.resize(cloud.size());
  cloud.normals.resize(cloud.size());
  if (neighbours != nullptr) {
    neighbours->k = std::min(k, cloud.size());
    neighbours->indices.resize(cloud.size() * neighbours->k);
    neighbours->radii.resize(cloud.size());
  }
  const double across_plane_reduction = 1.0 - config.plane_epsilon;
  parallel_for(cloud.size(), config.num_threads, [&](size_t begin, size_t end) {
    std::vector<uint32_t> indices(k);
    std::vector<float> distances(k);
    for (size_t i = begin; i < end; ++i) {
      const Eigen::Vector3f& position = cloud.positions[i];
      const size_t found = tree.knn(position, k, indices.data(), distances.data());
      if (neighbours != nullptr) {
        std::copy_n(indices.begin(), found, neighbours->indices.begin() + static_cast<std::ptrdiff_t>(i * neighbours->k));
        neighbours->radii[i] = found > 0 ? std::sqrt(distances[found - 1]) : 0.0f;
      }
      if (found < 3) {
        cloud.covariances[i] = Eigen::Matrix3f::Identity();
        const float range = position.norm();
        cloud.normals[i] = range > 0.0f ? Eigen::Vector3f(-position / range) : Eigen::Vector3f::UnitZ();
        continue;
      }
      // Offsets from the query point (within a metre or so: float keeps micrometres).
      Eigen::Vector3f mean = Eigen::Vector3f::Zero();
      for (size_t n = 0; n < found; ++n) mean += cloud.positions[indices[n]] - position;
      mean /= static_cast<float>(found);
      Eigen::Matrix3f scatter = Eigen::Matrix3f::Zero();
      for (size_t n = 0; n < found; ++n) {
        const Eigen::Vector3f d = cloud.positions[indices[n]] - position - mean;
        scatter.noalias() += d * d.transpose();
      }
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3f> solver;
      solver.computeDirect(scatter / static_cast<float>(found));
      // Eigenvalues (epsilon, 1, 1) in the eigenbasis: I - (1 - epsilon) n n^T for the normal n.
      const Eigen::Vector3f normal = solver.eigenvectors().col(0).normalized();  // smallest eigenvalue
      cloud.covariances[i] = Eigen::Matrix3f::Identity() - static_cast<float>(across_plane_reduction) * normal * normal.transpose();
      cloud.normals[i] = toward_origin(normal, position);
    }
  });
}

void estimate_local_geometry(PointCloud& cloud, const LocalGeometryConfig& config) {
  const KdTree tree(cloud.positions);
  estimate_local_geometry(cloud, tree, config);
}

}  // namespace hanzo::fusion::cloud
