#include "hanzo/fusion/cloud/voxel_grid.hpp"

#include <algorithm>
#include <cassert>
#include <utility>

#include <absl/container/flat_hash_set.h>

#include "hanzo/fusion/cloud/parallel.hpp"
#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::cloud {
namespace {

constexpr int kKeyBits = 21;
constexpr int64_t kKeyOffset = int64_t{1} << (kKeyBits - 1);
constexpr uint64_t kKeyMask = (uint64_t{1} << kKeyBits) - 1;
constexpr uint64_t kInvalidKey = ~uint64_t{0};

// The first candidate of each voxel within candidates[begin, end), in order, with its key.
struct FirstOfEachVoxel {
  std::vector<uint32_t> candidates;
  std::vector<uint64_t> keys;
};

FirstOfEachVoxel first_of_each_voxel(const std::vector<Eigen::Vector3f>& points, const std::vector<uint32_t>& candidates,
                                     size_t begin, size_t end, float inverse_voxel_size) {
  FirstOfEachVoxel first;
  absl::flat_hash_set<uint64_t> occupied;
  occupied.reserve((end - begin) / 4);
  // The keys seen last, by a hash of the key: neighbouring points of a scan mostly share a voxel,
  // and this small table answers them without the cache misses of the large set.
  std::vector<uint64_t> recent(4096, kInvalidKey);
  for (size_t n = begin; n < end; ++n) {
    uint64_t key = 0;
    if (!pack_voxel_key(voxel_coordinates(points[candidates[n]], inverse_voxel_size), &key)) continue;
    uint64_t& seen = recent[(key * 0x9E3779B97F4A7C15ULL) >> 52];
    if (seen == key) continue;
    seen = key;
    if (!occupied.insert(key).second) continue;
    first.candidates.push_back(candidates[n]);
    first.keys.push_back(key);
  }
  return first;
}

}  // namespace

Eigen::Vector3i unpack_voxel_key(uint64_t key) {
  Eigen::Vector3i voxel;
  for (int axis = 0; axis < 3; ++axis) voxel[axis] = static_cast<int>(int64_t((key >> (kKeyBits * axis)) & kKeyMask) - kKeyOffset);
  return voxel;
}

std::vector<uint32_t> first_point_per_voxel(const std::vector<Eigen::Vector3f>& points, const std::vector<uint32_t>& candidates,
                                            double voxel_size, int num_threads) {
  assert(voxel_size > 0);
  const float inverse = static_cast<float>(1.0 / voxel_size);
  if (thread_count(num_threads) == 1) return first_of_each_voxel(points, candidates, 0, candidates.size(), inverse).candidates;
  // Each chunk of consecutive candidates finds its own first per voxel in parallel; a voxel seen
  // by several chunks then keeps the first chunk's (chunks merged in order): the sequential result.
  std::vector<FirstOfEachVoxel> chunks(chunk_count(candidates.size()));
  parallel_chunks(candidates.size(), num_threads, [&](size_t chunk, size_t begin, size_t end) {
    chunks[chunk] = first_of_each_voxel(points, candidates, begin, end, inverse);
  });
  if (chunks.size() == 1) return std::move(chunks.front().candidates);
  size_t total = 0;
  for (const FirstOfEachVoxel& chunk : chunks) total += chunk.candidates.size();
  absl::flat_hash_set<uint64_t> occupied;
  occupied.reserve(total);
  std::vector<uint32_t> kept;
  kept.reserve(total);
  for (const FirstOfEachVoxel& chunk : chunks) {
    for (size_t n = 0; n < chunk.candidates.size(); ++n) {
      if (occupied.insert(chunk.keys[n]).second) kept.push_back(chunk.candidates[n]);
    }
  }
  return kept;
}

PointCloud voxel_downsample(const PointCloud& cloud, double voxel_size, int num_threads) {
  assert(voxel_size > 0.0);
  const float inverse_size = static_cast<float>(1.0 / voxel_size);
  std::vector<std::pair<uint64_t, uint32_t>> keyed(cloud.size());
  parallel_for(cloud.size(), num_threads, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) {
      uint64_t key = kInvalidKey;
      if (!pack_voxel_key(voxel_coordinates(cloud.positions[i], inverse_size), &key)) key = kInvalidKey;
      keyed[i] = {key, static_cast<uint32_t>(i)};
    }
  });
  std::sort(keyed.begin(), keyed.end());
  while (!keyed.empty() && keyed.back().first == kInvalidKey) keyed.pop_back();
  if (keyed.size() < cloud.size()) {
    logger()->warn("voxel_downsample: dropped {} points outside the voxel key range", cloud.size() - keyed.size());
  }

  PointCloud out;
  const auto reserve_like = [](const auto& from, auto& to, size_t count) {
    if (!from.empty()) to.reserve(count);
  };
  const size_t estimated = keyed.size() / 4 + 1;
  out.positions.reserve(estimated);
  reserve_like(cloud.intensities, out.intensities, estimated);
  reserve_like(cloud.rings, out.rings, estimated);
  reserve_like(cloud.times, out.times, estimated);
  reserve_like(cloud.normals, out.normals, estimated);
  reserve_like(cloud.covariances, out.covariances, estimated);

  for (size_t begin = 0; begin < keyed.size();) {
    size_t end = begin + 1;
    while (end < keyed.size() && keyed[end].first == keyed[begin].first) ++end;
    const float weight = 1.0f / static_cast<float>(end - begin);
    Eigen::Vector3d position_sum = Eigen::Vector3d::Zero();  // double: thousands of points per voxel in dense maps
    for (size_t k = begin; k < end; ++k) position_sum += cloud.positions[keyed[k].second].cast<double>();
    out.positions.push_back((position_sum / static_cast<double>(end - begin)).cast<float>());
    const auto average = [&](const auto& from, auto& to) {
      if (from.empty()) return;
      auto sum = from[keyed[begin].second];
      for (size_t k = begin + 1; k < end; ++k) sum += from[keyed[k].second];
      to.push_back(sum * weight);
    };
    average(cloud.intensities, out.intensities);
    average(cloud.times, out.times);
    average(cloud.covariances, out.covariances);
    if (cloud.has_normals()) {
      Eigen::Vector3f sum = Eigen::Vector3f::Zero();
      for (size_t k = begin; k < end; ++k) sum += cloud.normals[keyed[k].second];
      const float norm = sum.norm();
      out.normals.push_back(norm > 0.0f ? Eigen::Vector3f(sum / norm) : cloud.normals[keyed[begin].second]);
    }
    if (cloud.has_rings()) out.rings.push_back(cloud.rings[keyed[begin].second]);
    begin = end;
  }
  return out;
}

}  // namespace hanzo::fusion::cloud
