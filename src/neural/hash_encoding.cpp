#include "hanzo/fusion/neural/hash_encoding.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <tbb/parallel_for.h>

namespace hanzo::fusion::neural {

namespace {
constexpr std::size_t kBlock = 2048;  // points whose corners are computed (and prefetched) together
}  // namespace

Status validate(const HashGridConfig& config) {
  if (config.levels < 1 || config.levels > 64) return Error("HashGridConfig.levels: must be 1..64", "levels");
  if (config.features_per_level < 1 || config.features_per_level > 8) return Error("HashGridConfig.features_per_level: must be 1..8", "features_per_level");
  if (config.log2_table_size < 4 || config.log2_table_size > 26) return Error("HashGridConfig.log2_table_size: must be 4..26", "log2_table_size");
  if (config.base_resolution < 2 || config.finest_resolution < config.base_resolution || config.finest_resolution > (1 << 20)) {
    return Error(fmt::format("HashGridConfig: need 2 <= base_resolution ({}) <= finest_resolution ({}) <= 2^20", config.base_resolution,
                             config.finest_resolution));
  }
  return ok_status();
}

HashGrid::HashGrid(const HashGridConfig& config) : config_(config) {
  // Per-level growth b = exp((ln N_max - ln N_min) / (L - 1)) (eq. 3).
  const double growth =
      config.levels > 1 ? std::exp((std::log(config.finest_resolution) - std::log(config.base_resolution)) / (config.levels - 1)) : 1.0;
  const std::size_t table_size = std::size_t{1} << config.log2_table_size;
  level_offset_.push_back(0);
  for (int level = 0; level < config.levels; ++level) {
    const double scale = config.base_resolution * std::pow(growth, level) - 1.0;
    const auto resolution = static_cast<uint32_t>(std::ceil(scale)) + 1;
    scale_.push_back(scale);
    resolution_.push_back(resolution);
    const double dense = std::pow(static_cast<double>(resolution), 3.0);
    const std::size_t entries = dense < static_cast<double>(table_size) ? static_cast<std::size_t>(dense) : table_size;
    level_offset_.push_back(level_offset_.back() + entries);
  }
}

void HashGrid::corners(int level, const float* position, Corners& out) const {
  const auto l = static_cast<std::size_t>(level);
  const std::size_t entries = level_offset_[l + 1] - level_offset_[l];
  const uint32_t resolution = resolution_[l];
  const auto scale = static_cast<float>(scale_[l]);
  const bool dense = static_cast<double>(resolution) * resolution * resolution <= static_cast<double>(entries);
  uint32_t cell[3];
  float fraction[3];
  for (int axis = 0; axis < 3; ++axis) {
    const float x = std::clamp(position[axis], 0.0f, 1.0f) * scale + 0.5f;
    const float floor = std::floor(x);
    cell[axis] = static_cast<uint32_t>(floor);
    fraction[axis] = x - floor;
  }
  // Hashed levels hold exactly 2^log2_table_size entries: the modulo of eq. 4 is a mask.
  const uint32_t mask = static_cast<uint32_t>(entries - 1);
  for (int corner = 0; corner < 8; ++corner) {
    uint32_t vertex[3];
    float weight = 1.0f;
    for (int axis = 0; axis < 3; ++axis) {
      const bool upper = (corner >> axis) & 1;
      vertex[axis] = cell[axis] + (upper ? 1U : 0U);
      weight *= upper ? fraction[axis] : 1.0f - fraction[axis];
    }
    std::size_t index = 0;
    if (dense) {
      index = (static_cast<std::size_t>(std::min(vertex[2], resolution - 1)) * resolution + std::min(vertex[1], resolution - 1)) * resolution +
              std::min(vertex[0], resolution - 1);
    } else {
      index = (vertex[0] ^ (vertex[1] * 2654435761U) ^ (vertex[2] * 805459861U)) & mask;  // eq. 4
    }
    out.index[corner] = level_offset_[l] + index;
    out.weight[corner] = weight;
  }
}

void HashGrid::forward(const float* parameters, const float* positions, std::size_t count, float* features) const {
  const auto width = static_cast<std::size_t>(output_width());
  const auto feature_count = static_cast<std::size_t>(config_.features_per_level);
  // Blocks of points, level after level within a block: first every point's corners (their table
  // lines prefetched), then the blends, so that the table's cache misses overlap.
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, kBlock), [&](const tbb::blocked_range<std::size_t>& range) {
    std::vector<Corners> block(range.size());
    for (int level = 0; level < config_.levels; ++level) {
      for (std::size_t i = range.begin(); i != range.end(); ++i) {
        Corners& c = block[i - range.begin()];
        corners(level, positions + 3 * i, c);
        for (int corner = 0; corner < 8; ++corner) __builtin_prefetch(parameters + c.index[corner] * feature_count);
      }
      for (std::size_t i = range.begin(); i != range.end(); ++i) {
        const Corners& c = block[i - range.begin()];
        float* out = features + i * width + static_cast<std::size_t>(level) * feature_count;
        for (std::size_t f = 0; f < feature_count; ++f) {
          float sum = 0.0f;
          for (int corner = 0; corner < 8; ++corner) sum += c.weight[corner] * parameters[c.index[corner] * feature_count + f];
          out[f] = sum;
        }
      }
    }
  });
}

void HashGrid::backward(const float* positions, std::size_t count, const float* feature_gradient, float* gradient) const {
  const auto width = static_cast<std::size_t>(output_width());
  const auto feature_count = static_cast<std::size_t>(config_.features_per_level);
  // Levels own disjoint parameter ranges: one level per task, points in order within it (corners
  // of a block first, prefetched, then the scatter).
  tbb::parallel_for(0, config_.levels, [&](int level) {
    std::vector<Corners> block(kBlock);
    for (std::size_t first = 0; first < count; first += kBlock) {
      const std::size_t last = std::min(count, first + kBlock);
      for (std::size_t i = first; i < last; ++i) {
        Corners& c = block[i - first];
        corners(level, positions + 3 * i, c);
        for (int corner = 0; corner < 8; ++corner) __builtin_prefetch(gradient + c.index[corner] * feature_count, 1);
      }
      for (std::size_t i = first; i < last; ++i) {
        const Corners& c = block[i - first];
        const float* g = feature_gradient + i * width + static_cast<std::size_t>(level) * feature_count;
        for (int corner = 0; corner < 8; ++corner) {
          float* out = gradient + c.index[corner] * feature_count;
          for (std::size_t f = 0; f < feature_count; ++f) out[f] += c.weight[corner] * g[f];
        }
      }
    }
  });
}

}  // namespace hanzo::fusion::neural
