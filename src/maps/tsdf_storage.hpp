#pragma once
// The sparse voxel blocks of a TsdfVolume, shared by integration (tsdf.cpp) and mesh
// extraction (marching_cubes.cpp).

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/maps/tsdf.hpp"
#include "floor_divide.hpp"

namespace hanzo::fusion::maps {

struct TsdfStorage {
  /// Voxels are stored in 4 bytes: the distance as a 16-bit fraction of the truncation
  /// (steps of truncation / 32767, 5 micrometres at 0.15 m) and the weight as a 16-bit count.
  struct Block {
    std::vector<int16_t> distances;  // block_size^3, x fastest
    std::vector<uint16_t> weights;   // 0: unobserved
  };

  explicit TsdfStorage(const TsdfConfig& config)
      : distance_step(static_cast<float>(config.truncation() / 32767.0)),
        voxel_size(config.voxel_size),
        block_size(config.block_size),
        block_voxels(config.block_size * config.block_size * config.block_size),
        block_edge(config.voxel_size * config.block_size),
        max_weight(config.max_weight) {}

  float distance_step;  // meters per distance unit
  double voxel_size;
  int block_size;
  int block_voxels;
  double block_edge;
  float max_weight;
  std::unordered_map<uint64_t, std::unique_ptr<Block>> blocks;

  /// 21 bits per axis, offset by 2^20.
  static uint64_t block_key(const Eigen::Vector3i& block) {
    uint64_t key = 0;
    for (int axis = 0; axis < 3; ++axis) key = (key << 21) | (static_cast<uint64_t>(block[axis] + (1 << 20)) & ((uint64_t{1} << 21) - 1));
    return key;
  }
  static Eigen::Vector3i block_from_key(uint64_t key) {
    Eigen::Vector3i block;
    for (int axis = 2; axis >= 0; --axis) {
      block[axis] = static_cast<int>(key & ((uint64_t{1} << 21) - 1)) - (1 << 20);
      key >>= 21;
    }
    return block;
  }
  Eigen::Vector3i voxel_of_point(const Eigen::Vector3d& point) const {
    return (point / voxel_size).array().floor().cast<int>();
  }
  Eigen::Vector3i block_of_voxel(const Eigen::Vector3i& voxel) const {
    return {floor_divide(voxel.x(), block_size), floor_divide(voxel.y(), block_size), floor_divide(voxel.z(), block_size)};
  }
  Eigen::Vector3i block_of_point(const Eigen::Vector3d& point) const { return block_of_voxel(voxel_of_point(point)); }
  int offset_of(const Eigen::Vector3i& voxel, const Eigen::Vector3i& block) const {
    const Eigen::Vector3i local = voxel - block * block_size;
    return (local.z() * block_size + local.y()) * block_size + local.x();
  }
  Eigen::Vector3i voxel_at(const Eigen::Vector3i& block, int offset) const {
    return block * block_size + Eigen::Vector3i(offset % block_size, (offset / block_size) % block_size, offset / (block_size * block_size));
  }
  Eigen::Vector3d voxel_centre(const Eigen::Vector3i& block, int offset) const {
    return (voxel_at(block, offset).cast<double>().array() + 0.5) * voxel_size;
  }

  Block& find_or_create(uint64_t key) {
    auto& slot = blocks[key];
    if (!slot) {
      slot = std::make_unique<Block>();
      slot->distances.assign(static_cast<std::size_t>(block_voxels), 0);
      slot->weights.assign(static_cast<std::size_t>(block_voxels), 0);
    }
    return *slot;
  }
  std::pair<Block*, int> locate_or_create(const Eigen::Vector3i& voxel) {
    const Eigen::Vector3i block = block_of_voxel(voxel);
    return {&find_or_create(block_key(block)), offset_of(voxel, block)};
  }
  /// (distance, weight) of a voxel; weight 0 when unobserved.
  std::pair<float, float> voxel(const Eigen::Vector3i& voxel_index) const {
    const Eigen::Vector3i block = block_of_voxel(voxel_index);
    const auto found = blocks.find(block_key(block));
    if (found == blocks.end()) return {0.0f, 0.0f};
    const std::size_t offset = static_cast<std::size_t>(offset_of(voxel_index, block));
    return {distance_of(found->second->distances[offset]), static_cast<float>(found->second->weights[offset])};
  }
  float distance_of(int16_t stored) const { return static_cast<float>(stored) * distance_step; }
  int16_t stored_distance(float meters) const {
    return static_cast<int16_t>(std::clamp(std::lround(meters / distance_step), -32767L, 32767L));
  }
  /// Curless & Levoy's weighted running average with unit observation weight; sdf is within
  /// [-truncation, truncation].
  void update(Block& block, int offset, float sdf) const {
    int16_t& distance = block.distances[static_cast<std::size_t>(offset)];
    uint16_t& weight = block.weights[static_cast<std::size_t>(offset)];
    const float w = static_cast<float>(weight);
    distance = stored_distance((distance_of(distance) * w + sdf) / (w + 1.0f));
    weight = static_cast<uint16_t>(std::min(w + 1.0f, max_weight));
  }
  std::vector<uint64_t> sorted_keys() const {
    std::vector<uint64_t> keys;
    keys.reserve(blocks.size());
    for (const auto& [key, block] : blocks) keys.push_back(key);
    std::sort(keys.begin(), keys.end());
    return keys;
  }
};

/// The zero-crossing mesh of the volume (marching_cubes.cpp).
msgs::MeshLayer marching_cubes(const TsdfStorage& storage);

}  // namespace hanzo::fusion::maps
