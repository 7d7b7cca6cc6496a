#pragma once
// Voxel-grid downsampling: one point per occupied cubic voxel of edge `voxel_size`, at the
// centroid of the points in it (spec defaults: 0.05 m indoor, 0.2 m outdoor). Attributes
// follow the position: intensities, times, normals (renormalized) and covariances are
// averaged, rings are taken from the voxel's first point.
//
// Voxels are indexed by floor(p / voxel_size) packed into 21 bits per axis, so the grid spans
// +-2^20 voxels per axis around the origin (+-52 km at 0.05 m); points outside are dropped
// and counted in the log. The output is ordered by voxel index and does not depend on the
// input order or thread count (up to float rounding of the centroid).

#include <cstdint>

#include <Eigen/Core>

#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::cloud {

/// Voxel coordinates of `position` for voxels of edge `voxel_size` (m).
inline Eigen::Vector3i voxel_coordinates(const Eigen::Vector3f& position, float inverse_voxel_size) {
  return (position * inverse_voxel_size).array().floor().cast<int>();
}

/// The voxel's 63-bit key (21 bits per axis), or false when it lies outside the key range.
bool pack_voxel_key(const Eigen::Vector3i& voxel, uint64_t* key);
/// The voxel of a key made by pack_voxel_key.
Eigen::Vector3i unpack_voxel_key(uint64_t key);

/// Downsampled copy of `cloud`. voxel_size must be > 0 (m).
PointCloud voxel_downsample(const PointCloud& cloud, double voxel_size, int num_threads = 1);

}  // namespace hanzo::fusion::cloud
