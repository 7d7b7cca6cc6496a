#include "hanzo/fusion/cloud/voxel_hash_map.hpp"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>

#include "hanzo/fusion/cloud/parallel.hpp"
#include "hanzo/fusion/cloud/voxel_grid.hpp"

namespace hanzo::fusion::cloud {
namespace {

// The 27 voxels around a query in the order nearest_k() visits them, one order per octant of
// the query's voxel that the query lies in (bit a set: upper half along axis a): its own voxel
// first, then those on the query's side before those across (a voxel across lies at least half
// an edge farther), so the k-nearest bound shrinks early and prunes the rest.
using NeighbourOrder = std::array<Eigen::Vector3i, 27>;
const std::array<NeighbourOrder, 8> kNeighbourOrders = [] {
  std::array<NeighbourOrder, 8> orders;
  for (int octant = 0; octant < 8; ++octant) {
    const auto cost = [octant](const Eigen::Vector3i& offset) {
      int total = 0;
      for (int axis = 0; axis < 3; ++axis) {
        const int toward = (octant >> axis) & 1 ? 1 : -1;
        total += offset[axis] == 0 ? 0 : (offset[axis] == toward ? 1 : 3);
      }
      return total;
    };
    std::vector<Eigen::Vector3i> offsets;
    for (int dx = -1; dx <= 1; ++dx) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dz = -1; dz <= 1; ++dz) offsets.emplace_back(dx, dy, dz);
      }
    }
    std::stable_sort(offsets.begin(), offsets.end(), [&](const Eigen::Vector3i& a, const Eigen::Vector3i& b) { return cost(a) < cost(b); });
    std::copy(offsets.begin(), offsets.end(), orders[octant].begin());
  }
  return orders;
}();

// The points of a voxel, or nullptr: find(), inlined into the searches (a call per neighbouring
// voxel otherwise, up to 27 a query).
[[gnu::always_inline]] inline const std::vector<MapPoint>* points_of(const absl::flat_hash_map<uint64_t, std::vector<MapPoint>>& voxels,
                                                                     const Eigen::Vector3i& voxel_coordinates) {
  uint64_t key = 0;
  if (!pack_voxel_key(voxel_coordinates, &key)) return nullptr;
  const auto it = voxels.find(key);
  return it == voxels.end() ? nullptr : &it->second;
}

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
                       const Eigen::Vector3d& sensor_origin, int num_threads) {
  assert(normals.empty() || normals.size() == points.size());
  add(points, sensor_origin, [&normals](std::size_t i) { return normals.empty() ? Eigen::Vector3f::Zero().eval() : normals[i]; },
      num_threads);
}

bool VoxelHashMap::refuses(const std::vector<MapPoint>& voxel, const Eigen::Vector3f& point) const {
  if (voxel.size() >= static_cast<size_t>(config_.max_points_per_voxel)) return true;
  for (const MapPoint& existing : voxel) {
    if ((existing.position - point).squaredNorm() < min_spacing_squared_) return true;
  }
  return false;
}

void VoxelHashMap::add(const std::vector<Eigen::Vector3f>& points, const Eigen::Vector3d& sensor_origin,
                       const std::function<Eigen::Vector3f(std::size_t)>& normal_of, int num_threads) {
  if (thread_count(num_threads) == 1) {
    for (size_t i = 0; i < points.size(); ++i) {
      uint64_t key = 0;
      if (!points[i].allFinite() || !pack_voxel_key(coordinates(points[i]), &key)) {
        ++skipped_points_;
        continue;
      }
      std::vector<MapPoint>& voxel = voxels_[key];
      if (!refuses(voxel, points[i])) place(voxel, points[i], normal_of(i));
    }
  } else {
    add_in_parallel(points, normal_of, num_threads);
  }
  remove_farther_than(sensor_origin);
}

void VoxelHashMap::place(std::vector<MapPoint>& voxel, const Eigen::Vector3f& point, const Eigen::Vector3f& normal) {
  if (voxel.empty()) voxel.reserve(static_cast<size_t>(config_.max_points_per_voxel));
  voxel.push_back({point, normal.allFinite() ? normal : Eigen::Vector3f::Zero()});
  ++point_count_;
}

void VoxelHashMap::add_in_parallel(const std::vector<Eigen::Vector3f>& points,
                                   const std::function<Eigen::Vector3f(std::size_t)>& normal_of, int num_threads) {
  // 1. In parallel, against the map as it stands: each point's key, and whether its voxel refuses
  //    it already (full, or a point within the spacing). Within one add voxels only gain points,
  //    so such a point would be refused in order too; the others (mostly new surface) are
  //    candidates, with their normals.
  enum Fate : uint8_t { kRefused, kOutsideKeyRange, kCandidate };
  std::vector<uint64_t> keys(points.size());
  std::vector<Fate> fates(points.size());
  std::vector<Eigen::Vector3f> normals(points.size());
  parallel_for(points.size(), num_threads, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) {
      const Eigen::Vector3f& point = points[i];
      if (!point.allFinite() || !pack_voxel_key(coordinates(point), &keys[i])) {
        fates[i] = kOutsideKeyRange;
        continue;
      }
      const auto voxel = voxels_.find(keys[i]);
      fates[i] = voxel != voxels_.end() && refuses(voxel->second, point) ? kRefused : kCandidate;
      if (fates[i] == kCandidate) normals[i] = normal_of(i);
    }
  });
  // 2. The candidates in order, against the points this add has placed too.
  for (size_t i = 0; i < points.size(); ++i) {
    if (fates[i] == kOutsideKeyRange) ++skipped_points_;
    if (fates[i] != kCandidate) continue;
    std::vector<MapPoint>& voxel = voxels_[keys[i]];
    if (!refuses(voxel, points[i])) place(voxel, points[i], normals[i]);
  }
}

void VoxelHashMap::remove_farther_than(const Eigen::Vector3d& sensor_origin) {
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
  return points_of(voxels_, voxel_coordinates);
}

bool VoxelHashMap::nearest(const Eigen::Vector3f& query, Eigen::Vector3f* point, float* squared_distance) const {
  const Eigen::Vector3i center = coordinates(query);
  float best = std::numeric_limits<float>::infinity();
  for (int dx = -1; dx <= 1; ++dx) {
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dz = -1; dz <= 1; ++dz) {
        const std::vector<MapPoint>* voxel = points_of(voxels_, center + Eigen::Vector3i(dx, dy, dz));
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
  // The best k so far, sorted by squared distance (k is small: 5-20), in a per-thread buffer
  // reached through a local pointer (through the thread_local vector itself, every insertion
  // reloaded it: a fifth of this search's time).
  struct Candidate {
    float squared_distance;
    const MapPoint* point;
  };
  thread_local std::vector<Candidate> storage;
  if (storage.size() < k) storage.resize(k);
  Candidate* const best = storage.data();
  std::size_t count = 0;
  float bound = max_distance * max_distance;
  const Eigen::Vector3i center = coordinates(query);
  // Offset of the query inside its voxel, to skip neighbour voxels farther than the bound.
  const float voxel_size = static_cast<float>(config_.voxel_size);
  const Eigen::Vector3f low = query - center.cast<float>() * voxel_size;  // in [0, voxel_size)
  const Eigen::Vector3f high = Eigen::Vector3f::Constant(voxel_size) - low;
  const int octant = (low.x() > high.x() ? 1 : 0) | (low.y() > high.y() ? 2 : 0) | (low.z() > high.z() ? 4 : 0);
  for (const Eigen::Vector3i& offset : kNeighbourOrders[static_cast<std::size_t>(octant)]) {
    float box_squared = 0.0F;
    for (int axis = 0; axis < 3; ++axis) {
      const float gap = offset[axis] < 0 ? low[axis] : (offset[axis] > 0 ? high[axis] : 0.0F);
      box_squared += gap * gap;
    }
    if (box_squared >= bound) continue;
    const std::vector<MapPoint>* voxel = points_of(voxels_, center + offset);
    if (voxel == nullptr) continue;
    for (const MapPoint& candidate : *voxel) {
      const float d = (candidate.position - query).squaredNorm();
      if (d >= bound) continue;
      // Insertion from the back; the last one falls off when k are held.
      std::size_t slot = count < k ? count++ : k - 1;
      while (slot > 0 && best[slot - 1].squared_distance > d) {
        best[slot] = best[slot - 1];
        --slot;
      }
      best[slot] = {d, &candidate};
      if (count == k) bound = best[k - 1].squared_distance;
    }
  }
  for (std::size_t n = 0; n < count; ++n) neighbours->push_back(*best[n].point);
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
