#pragma once
// The target side of NDT: one Gaussian per occupied voxel (Magnusson 2009, sec. 6.1), with the
// covariance regularized so that no eigenvalue is below 1 % of the largest (eq. 6.11, which
// keeps flat cells invertible).

#include <cstdint>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/lidar/registration.hpp"

namespace hanzo::fusion::lidar {

struct NdtCell {
  Eigen::Vector3d mean;
  Eigen::Matrix3d inverse_covariance;
};

class NdtGrid {
 public:
  NdtGrid(const std::vector<Eigen::Vector3f>& points, const NdtConfig& config);

  size_t size() const { return cells_.size(); }
  double resolution() const { return resolution_; }

  /// Calls visit(cell) for the Gaussians of the voxel holding `point` and its 6 face neighbours
  /// (the "DIRECT7" neighbourhood of ndt_omp / PCL's VoxelGridCovariance).
  template <typename Visit>
  void for_each_neighbor(const Eigen::Vector3d& point, Visit&& visit) const {
    static const Eigen::Vector3i kOffsets[7] = {{0, 0, 0},  {1, 0, 0}, {-1, 0, 0}, {0, 1, 0},
                                                {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    const Eigen::Vector3i voxel = (point * inverse_resolution_).array().floor().cast<int>();
    for (const Eigen::Vector3i& offset : kOffsets) {
      const auto found = cells_.find(key(voxel + offset));
      if (found != cells_.end()) visit(found->second);
    }
  }

 private:
  static uint64_t key(const Eigen::Vector3i& voxel);

  double resolution_;
  double inverse_resolution_;
  std::unordered_map<uint64_t, NdtCell> cells_;
};

/// Magnusson's d1, d2 of the Gaussian-plus-uniform score approximation (thesis eq. 6.8).
struct NdtScoreConstants {
  double d1 = 0.0;  // < 0
  double d2 = 0.0;  // > 0
};
NdtScoreConstants ndt_score_constants(const NdtConfig& config);

}  // namespace hanzo::fusion::lidar
