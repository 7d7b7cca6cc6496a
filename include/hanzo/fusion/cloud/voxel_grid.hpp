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

#include <algorithm>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::cloud {

/// floor(value) as an integer, inlined (std::floor is a library call on baseline x86-64: a third
/// of the time of hashing a scan into voxels). Values beyond +-2^30 are clamped there; finite
/// input only.
inline int floor_to_int(float value) {
  const float clamped = std::clamp(value, -1073741824.0F, 1073741824.0F);
  const int truncated = static_cast<int>(clamped);
  return truncated - static_cast<int>(clamped < static_cast<float>(truncated));
}

/// Voxel coordinates of `position` (finite) for voxels of edge 1 / inverse_voxel_size (m).
inline Eigen::Vector3i voxel_coordinates(const Eigen::Vector3f& position, float inverse_voxel_size) {
  return {floor_to_int(position.x() * inverse_voxel_size), floor_to_int(position.y() * inverse_voxel_size),
          floor_to_int(position.z() * inverse_voxel_size)};
}

/// The voxel's 63-bit key (21 bits per axis), or false when it lies outside the key range.
inline bool pack_voxel_key(const Eigen::Vector3i& voxel, uint64_t* key) {
  constexpr int kBits = 21;
  constexpr int64_t kOffset = int64_t{1} << (kBits - 1);
  constexpr uint64_t kMask = (uint64_t{1} << kBits) - 1;
  uint64_t packed = 0;
  for (int axis = 0; axis < 3; ++axis) {
    const int64_t shifted = int64_t{voxel[axis]} + kOffset;
    if (shifted < 0 || static_cast<uint64_t>(shifted) > kMask) return false;
    packed |= static_cast<uint64_t>(shifted) << (kBits * axis);
  }
  *key = packed;
  return true;
}
/// The voxel of a key made by pack_voxel_key.
Eigen::Vector3i unpack_voxel_key(uint64_t key);

/// The first of `candidates` (indices into `points`) in each voxel of edge voxel_size (m, > 0),
/// in candidate order: an O(n) downsampling that keeps measured points, so their per-point
/// attributes stay valid. Points outside the key range are dropped. The same on any number of
/// threads (num_threads: see parallel.hpp).
std::vector<uint32_t> first_point_per_voxel(const std::vector<Eigen::Vector3f>& points, const std::vector<uint32_t>& candidates,
                                            double voxel_size, int num_threads = 1);

/// Downsampled copy of `cloud`. voxel_size must be > 0 (m).
PointCloud voxel_downsample(const PointCloud& cloud, double voxel_size, int num_threads = 1);

}  // namespace hanzo::fusion::cloud
