#include "hanzo/fusion/cloud/voxel_hash_map.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>

#include "hanzo/fusion/cloud/voxel_grid.hpp"

namespace hanzo::fusion::cloud {
namespace {

// The 27 voxels around a query, its own first, then faces, edges and corners (nearest first,
// so the k-nearest bound shrinks early and prunes the rest).
const std::vector<Eigen::Vector3i> kNeighbourOffsets = [] {
  std::vector<Eigen::Vector3i> offsets;
  for (int dx = -1; dx <= 1; ++dx) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dz = -1; dz <= 1; ++dz) offsets.emplace_back(dx, dy, dz);
    }
  }
  std::stable_sort(offsets.begin(), offsets.end(),
                   [](const Eigen::Vector3i& a, const Eigen::Vector3i& b) { return a.cwiseAbs().sum() < b.cwiseAbs().sum(); });
  return offsets;
}();

}  // namespace

VoxelHashMap::VoxelHashMap(VoxelHashMapConfig config)
    : config_(config), inverse_voxel_size_(static_cast<float>(1.0 / config.voxel_size)) {
  assert(config.voxel_size > 0.0 && config.max_points_per_voxel >= 1 && config.max_distance > 0.0);
  point_spacing_ = config.min_point_spacing < 0.0
                       ? config.voxel_size / std::sqrt(static_cast<double>(config.max_points_per_voxel))
                       : config.min_point_spacing;
  min_spacing_squared_ = static_cast<float>(point_spacing_ * point_spacing_);
}

void VoxelHashMap::clear() {
  voxels_.clear();
  point_count_ = 0;
}

void VoxelHashMap::add(const std::vector<Eigen::Vector3f>& points, const std::vector<Eigen::Vector3f>& normals,
                       const Eigen::Vector3d& sensor_origin) {
  assert(normals.empty() || normals.size() == points.size());
  add(points, sensor_origin, [&normals](std::size_t i) { return normals.empty() ? Eigen::Vector3f::Zero().eval() : normals[i]; });
}

void VoxelHashMap::add(const std::vector<Eigen::Vector3f>& points, const Eigen::Vector3d& sensor_origin,
                       const std::function<Eigen::Vector3f(std::size_t)>& normal_of) {
  const size_t max_points = static_cast<size_t>(config_.max_points_per_voxel);
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3f& point = points[i];
    uint64_t key = 0;
    if (!point.allFinite() || !pack_voxel_key(coordinates(point), &key)) {
      ++skipped_points_;
      continue;
    }
    std::vector<MapPoint>& voxel = voxels_[key];
    if (voxel.size() >= max_points) continue;
    bool crowded = false;
    for (const MapPoint& existing : voxel) {
      if ((existing.position - point).squaredNorm() < min_spacing_squared_) {
        crowded = true;
        break;
      }
    }
    if (crowded) continue;
    if (voxel.empty()) voxel.reserve(max_points);
    const Eigen::Vector3f normal = normal_of(i);
    voxel.push_back({point, normal.allFinite() ? normal : Eigen::Vector3f::Zero()});
    ++point_count_;
  }

  const float max_distance_squared = static_cast<float>(config_.max_distance * config_.max_distance);
  const Eigen::Vector3f origin = sensor_origin.cast<float>();
  // By the voxel's centre, from its key: reading its first point would miss the cache once per
  // voxel of the map.
  const float voxel_size = 1.0F / inverse_voxel_size_;
  absl::erase_if(voxels_, [&](const auto& entry) {
    const std::vector<MapPoint>& voxel = entry.second;
    const Eigen::Vector3i coordinates = unpack_voxel_key(entry.first);
    const Eigen::Vector3f centre = (coordinates.cast<float>().array() + 0.5F) * voxel_size;
    if (!voxel.empty() && (centre - origin).squaredNorm() <= max_distance_squared) return false;
    point_count_ -= voxel.size();
    return true;
  });
}

const std::vector<MapPoint>* VoxelHashMap::find(const Eigen::Vector3i& voxel_coordinates) const {
  uint64_t key = 0;
  if (!pack_voxel_key(voxel_coordinates, &key)) return nullptr;
  const auto it = voxels_.find(key);
  return it == voxels_.end() ? nullptr : &it->second;
}

bool VoxelHashMap::nearest(const Eigen::Vector3f& query, Eigen::Vector3f* point, float* squared_distance) const {
  const Eigen::Vector3i center = coordinates(query);
  float best = std::numeric_limits<float>::infinity();
  for (int dx = -1; dx <= 1; ++dx) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dz = -1; dz <= 1; ++dz) {
        const std::vector<MapPoint>* voxel = find(center + Eigen::Vector3i(dx, dy, dz));
        if (voxel == nullptr) continue;
        for (const MapPoint& candidate : *voxel) {
          const float d = (candidate.position - query).squaredNorm();
          if (d < best) {
            best = d;
            *point = candidate.position;
          }
        }
      }
    }
  }
  if (!std::isfinite(best)) return false;
  *squared_distance = best;
  return true;
}

void VoxelHashMap::nearest_k(const Eigen::Vector3f& query, std::size_t k, float max_distance,
                             std::vector<MapPoint>* neighbours) const {
  neighbours->clear();
  if (k == 0) return;
  // A sorted list of at most k (squared distance, point) pairs; k is small (5-10).
  thread_local std::vector<std::pair<float, MapPoint>> best;
  best.clear();
  float bound = max_distance * max_distance;
  const Eigen::Vector3i center = coordinates(query);
  // Offset of the query inside its voxel, to skip neighbour voxels farther than the bound.
  const float voxel_size = static_cast<float>(config_.voxel_size);
  const Eigen::Vector3f low = query - center.cast<float>() * voxel_size;  // in [0, voxel_size)
  const Eigen::Vector3f high = Eigen::Vector3f::Constant(voxel_size) - low;
  for (const Eigen::Vector3i& offset : kNeighbourOffsets) {
    float box_squared = 0.0F;
    for (int axis = 0; axis < 3; ++axis) {
      const float gap = offset[axis] < 0 ? low[axis] : (offset[axis] > 0 ? high[axis] : 0.0F);
      box_squared += gap * gap;
    }
    if (box_squared >= bound) continue;
    const std::vector<MapPoint>* voxel = find(center + offset);
    if (voxel == nullptr) continue;
    for (const MapPoint& candidate : *voxel) {
      const float d = (candidate.position - query).squaredNorm();
      if (d >= bound) continue;
      auto position = std::upper_bound(best.begin(), best.end(), d,
                                       [](float value, const auto& entry) { return value < entry.first; });
      best.insert(position, {d, candidate});
      if (best.size() > k) best.pop_back();
      if (best.size() == k) bound = best.back().first;
    }
  }
  for (const auto& entry : best) neighbours->push_back(entry.second);
}

std::vector<Eigen::Vector3f> VoxelHashMap::points() const {
  std::vector<Eigen::Vector3f> all;
  all.reserve(point_count_);
  for (const auto& [key, voxel] : voxels_) {
    for (const MapPoint& point : voxel) all.push_back(point.position);
  }
  return all;
}

std::size_t VoxelHashMap::memory_bytes() const {
  std::size_t bytes = voxels_.capacity() * (sizeof(std::pair<const uint64_t, std::vector<MapPoint>>) + 1);
  for (const auto& [key, voxel] : voxels_) bytes += voxel.capacity() * sizeof(MapPoint);
  return bytes;
}

}  // namespace hanzo::fusion::cloud
