#include "ndt_grid.hpp"

#include <cmath>

#include <Eigen/Eigenvalues>

namespace hanzo::fusion::lidar {
namespace {

struct CellSums {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();
  int count = 0;
};

}  // namespace

uint64_t NdtGrid::key(const Eigen::Vector3i& voxel) {
  // 21 bits per axis, wrapping: cells 2^21 voxels apart share a key, which never happens within
  // one registration target (2 000 km at 1 m cells).
  constexpr uint64_t kMask = (uint64_t{1} << 21) - 1;
  return (static_cast<uint64_t>(voxel.x()) & kMask) | ((static_cast<uint64_t>(voxel.y()) & kMask) << 21) |
         ((static_cast<uint64_t>(voxel.z()) & kMask) << 42);
}

NdtGrid::NdtGrid(const std::vector<Eigen::Vector3f>& points, const NdtConfig& config)
    : resolution_(config.resolution), inverse_resolution_(1.0 / config.resolution) {
  std::unordered_map<uint64_t, CellSums> sums;
  for (const Eigen::Vector3f& p : points) {
    const Eigen::Vector3d point = p.cast<double>();
    CellSums& cell = sums[key((point * inverse_resolution_).array().floor().cast<int>())];
    cell.sum += point;
    cell.outer.noalias() += point * point.transpose();
    ++cell.count;
  }
  cells_.reserve(sums.size());
  for (const auto& [cell_key, cell] : sums) {
    if (cell.count < config.min_points_per_cell) continue;
    const double n = cell.count;
    const Eigen::Vector3d mean = cell.sum / n;
    const Eigen::Matrix3d covariance = (cell.outer - n * mean * mean.transpose()) / (n - 1.0);
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
    Eigen::Vector3d eigenvalues = solver.eigenvalues();
    const double floor = 0.01 * eigenvalues.maxCoeff();
    if (!(floor > 0.0)) continue;  // all points identical
    eigenvalues = eigenvalues.cwiseMax(floor);
    cells_.emplace(cell_key, NdtCell{mean, solver.eigenvectors() * eigenvalues.cwiseInverse().asDiagonal() *
                                               solver.eigenvectors().transpose()});
  }
}

NdtScoreConstants ndt_score_constants(const NdtConfig& config) {
  const double c1 = 10.0 * (1.0 - config.outlier_ratio);
  const double c2 = config.outlier_ratio / std::pow(config.resolution, 3);
  const double d3 = -std::log(c2);
  NdtScoreConstants constants;
  constants.d1 = -std::log(c1 + c2) - d3;
  constants.d2 = -2.0 * std::log((-std::log(c1 * std::exp(-0.5) + c2) - d3) / constants.d1);
  return constants;
}

}  // namespace hanzo::fusion::lidar
