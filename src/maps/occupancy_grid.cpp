#include "hanzo/fusion/maps/occupancy_grid.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <unordered_map>

#include <fmt/format.h>

#include "floor_divide.hpp"

#include "layer_checks.hpp"

namespace hanzo::fusion::maps {
namespace {

/// Cell indices are limited to [-kIndexLimit, kIndexLimit) per axis, so that block indices fit
/// in 21 bits each of the 64-bit block key.
constexpr int kIndexLimit = 1 << 22;
/// Stamp of cells read from a layer: observed, but by no scan (scans use 1 .. max - 1).
constexpr uint32_t kImportedStamp = std::numeric_limits<uint32_t>::max();

}  // namespace

Status OccupancyConfig::validate() const {
  const auto open_unit = [](double value) { return std::isfinite(value) && value > 0.0 && value < 1.0; };
  if (!(std::isfinite(resolution) && resolution > 0.0)) {
    return Error{fmt::format("occupancy.resolution: must be a positive number of meters, got {}", resolution), "resolution"};
  }
  if (!open_unit(probability_hit) || probability_hit <= 0.5) {
    return Error{fmt::format("occupancy.probability_hit: must be in (0.5, 1), got {}", probability_hit), "probability_hit"};
  }
  if (!open_unit(probability_miss) || probability_miss >= 0.5) {
    return Error{fmt::format("occupancy.probability_miss: must be in (0, 0.5), got {}", probability_miss), "probability_miss"};
  }
  if (!open_unit(probability_min) || probability_min >= 0.5) {
    return Error{fmt::format("occupancy.probability_min: must be in (0, 0.5), got {}", probability_min), "probability_min"};
  }
  if (!open_unit(probability_max) || probability_max <= 0.5) {
    return Error{fmt::format("occupancy.probability_max: must be in (0.5, 1), got {}", probability_max), "probability_max"};
  }
  if (!open_unit(occupied_threshold) || !open_unit(free_threshold) || free_threshold >= occupied_threshold) {
    return Error{fmt::format("occupancy thresholds: need 0 < free_threshold < occupied_threshold < 1, got {} and {}",
                             free_threshold, occupied_threshold),
                 "free_threshold"};
  }
  if (!(std::isfinite(max_range) && max_range >= 0.0)) {
    return Error{fmt::format("occupancy.max_range: must be >= 0 meters (0: no limit), got {}", max_range), "max_range"};
  }
  return ok_status();
}

Result<Eigen::Vector3i> occupancy_layer_first_cell(const msgs::OccupancyGridLayer& layer) {
  if (!layer.origin.orientation.isApprox(Eigen::Quaterniond::Identity(), 1e-9) &&
      !layer.origin.orientation.isApprox(Eigen::Quaterniond(-1, 0, 0, 0), 1e-9)) {
    return Error{"occupancy layer: rotated grid origins are not supported (the origin's orientation must be identity)",
                 "occupancy.origin.orientation"};
  }
  const Eigen::Vector3d origin_cells = layer.origin.position / layer.resolution;
  const Eigen::Vector3d rounded = origin_cells.array().round();
  if (!origin_cells.allFinite() || (origin_cells - rounded).cwiseAbs().maxCoeff() > 1e-6 ||
      (rounded.array().abs() >= kIndexLimit / 2).any()) {
    return Error{fmt::format("occupancy layer: origin ({}, {}, {}) is not a whole number of cells from the world origin",
                             layer.origin.position.x(), layer.origin.position.y(), layer.origin.position.z()),
                 "occupancy.origin.position"};
  }
  return rounded.cast<int>().eval();
}

double probability_to_log_odds(double probability) { return std::log(probability / (1.0 - probability)); }
double log_odds_to_probability(double log_odds) { return 1.0 / (1.0 + std::exp(-log_odds)); }

template <int Dim>
struct OccupancyGrid<Dim>::Storage {
  static constexpr int kBlockEdge = Dim == 2 ? 32 : 8;
  static constexpr int kBlockCells = Dim == 2 ? kBlockEdge * kBlockEdge : kBlockEdge * kBlockEdge * kBlockEdge;

  struct Block {
    std::array<float, kBlockCells> log_odds{};
    /// Scan id of the last update; 0: never observed.
    std::array<uint32_t, kBlockCells> stamp{};
  };

  std::unordered_map<uint64_t, std::unique_ptr<Block>> blocks;
  // The block of the last lookup: rays visit long runs of cells in the same block.
  mutable uint64_t cached_key = std::numeric_limits<uint64_t>::max();
  mutable Block* cached_block = nullptr;

  static Index block_of(const Index& cell) {
    Index block;
    for (int axis = 0; axis < Dim; ++axis) block[axis] = floor_divide(cell[axis], kBlockEdge);
    return block;
  }
  static uint64_t key_of(const Index& block) {
    uint64_t key = 0;
    for (int axis = 0; axis < Dim; ++axis) {
      key = (key << 21) | (static_cast<uint64_t>(block[axis] + (1 << 20)) & ((uint64_t{1} << 21) - 1));
    }
    return key;
  }
  static Index block_from_key(uint64_t key) {
    Index block;
    for (int axis = Dim - 1; axis >= 0; --axis) {
      block[axis] = static_cast<int>(key & ((uint64_t{1} << 21) - 1)) - (1 << 20);
      key >>= 21;
    }
    return block;
  }
  static int offset_in_block(const Index& cell, const Index& block) {
    int offset = 0;
    for (int axis = Dim - 1; axis >= 0; --axis) offset = offset * kBlockEdge + (cell[axis] - block[axis] * kBlockEdge);
    return offset;
  }
  static Index cell_in_block(const Index& block, int offset) {
    Index cell;
    for (int axis = 0; axis < Dim; ++axis) {
      cell[axis] = block[axis] * kBlockEdge + offset % kBlockEdge;
      offset /= kBlockEdge;
    }
    return cell;
  }

  Block* find(const Index& block) const {
    const uint64_t key = key_of(block);
    if (key == cached_key) return cached_block;
    const auto found = blocks.find(key);
    if (found == blocks.end()) return nullptr;
    cached_key = key;
    cached_block = found->second.get();
    return cached_block;
  }
  Block& find_or_create(const Index& block) {
    if (Block* existing = find(block)) return *existing;
    auto& slot = blocks[key_of(block)];
    slot = std::make_unique<Block>();
    cached_key = key_of(block);
    cached_block = slot.get();
    return *slot;
  }
};

template <int Dim>
OccupancyGrid<Dim>::OccupancyGrid(const OccupancyConfig& config)
    : config_(config),
      log_odds_hit_(static_cast<float>(probability_to_log_odds(config.probability_hit))),
      log_odds_miss_(static_cast<float>(probability_to_log_odds(config.probability_miss))),
      log_odds_min_(static_cast<float>(probability_to_log_odds(config.probability_min))),
      log_odds_max_(static_cast<float>(probability_to_log_odds(config.probability_max))),
      storage_(std::make_unique<Storage>()) {}

template <int Dim>
Result<OccupancyGrid<Dim>> OccupancyGrid<Dim>::create(const OccupancyConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  return OccupancyGrid(config);
}

template <int Dim>
OccupancyGrid<Dim>::~OccupancyGrid() = default;
template <int Dim>
OccupancyGrid<Dim>::OccupancyGrid(OccupancyGrid&&) noexcept = default;
template <int Dim>
OccupancyGrid<Dim>& OccupancyGrid<Dim>::operator=(OccupancyGrid&&) noexcept = default;

template <int Dim>
OccupancyGrid<Dim>::OccupancyGrid(const OccupancyGrid& other)
    : config_(other.config_),
      log_odds_hit_(other.log_odds_hit_),
      log_odds_miss_(other.log_odds_miss_),
      log_odds_min_(other.log_odds_min_),
      log_odds_max_(other.log_odds_max_),
      scan_count_(other.scan_count_),
      storage_(std::make_unique<Storage>()) {
  for (const auto& [key, block] : other.storage_->blocks) {
    storage_->blocks.emplace(key, std::make_unique<typename Storage::Block>(*block));
  }
}

template <int Dim>
OccupancyGrid<Dim>& OccupancyGrid<Dim>::operator=(const OccupancyGrid& other) {
  if (this != &other) *this = OccupancyGrid(other);
  return *this;
}

template <int Dim>
typename OccupancyGrid<Dim>::Index OccupancyGrid<Dim>::cell_index(const Point& point) const {
  return (point / config_.resolution).array().floor().template cast<int>();
}

template <int Dim>
typename OccupancyGrid<Dim>::Point OccupancyGrid<Dim>::cell_center(const Index& cell) const {
  return (cell.template cast<double>().array() + 0.5) * config_.resolution;
}

template <int Dim>
Status OccupancyGrid<Dim>::insert_scan(const Point& sensor_origin, std::span<const Point> end_points) {
  const double limit = (kIndexLimit - 1) * config_.resolution;
  const auto in_range = [limit](const Point& point) {
    return point.allFinite() && (point.array().abs() < limit).all();
  };
  if (!in_range(sensor_origin)) {
    return Error{fmt::format("insert_scan: sensor origin is not finite or outside the grid (|coordinate| < {} m)", limit),
                 "sensor_origin"};
  }
  for (std::size_t i = 0; i < end_points.size(); ++i) {
    if (!in_range(end_points[i])) {
      return Error{fmt::format("insert_scan: end point {} is not finite or outside the grid (|coordinate| < {} m)", i, limit),
                   fmt::format("end_points[{}]", i)};
    }
  }

  ++scan_count_;
  const uint32_t stamp = static_cast<uint32_t>(scan_count_ % (kImportedStamp - 1)) + 1;
  Storage& storage = *storage_;
  const auto update = [&](const Index& cell, float delta) {
    const Index block_index = Storage::block_of(cell);
    auto& block = storage.find_or_create(block_index);
    const int offset = Storage::offset_in_block(cell, block_index);
    if (block.stamp[offset] == stamp) return;  // already updated by this scan
    block.stamp[offset] = stamp;
    block.log_odds[offset] = std::clamp(block.log_odds[offset] + delta, log_odds_min_, log_odds_max_);
  };

  // End points first, so that the rays of this scan never clear a cell it hit.
  const double max_range = config_.max_range;
  const auto beyond_range = [&](const Point& end) {
    return max_range > 0.0 && (end - sensor_origin).squaredNorm() > max_range * max_range;
  };
  for (const Point& end : end_points) {
    if (!beyond_range(end)) update(cell_index(end), log_odds_hit_);
  }

  // Free cells along each ray (Amanatides & Woo 1987 voxel traversal), from the origin's cell
  // up to and excluding the end point's cell; cut rays include their last cell.
  const Point origin_scaled = sensor_origin / config_.resolution;
  for (const Point& end_point : end_points) {
    Point end = end_point;
    const bool cut = beyond_range(end);
    if (cut) end = sensor_origin + (end - sensor_origin) * (max_range / (end - sensor_origin).norm());
    const Point direction = end / config_.resolution - origin_scaled;
    Index cell = cell_index(sensor_origin);
    const Index last = cell_index(end);
    Index step;
    Point next_boundary;  // ray parameter t in [0, 1] of the next boundary crossing per axis
    Point t_delta;
    int remaining = 0;
    for (int axis = 0; axis < Dim; ++axis) {
      remaining += std::abs(last[axis] - cell[axis]);
      if (direction[axis] > 0.0) {
        step[axis] = 1;
        next_boundary[axis] = (cell[axis] + 1 - origin_scaled[axis]) / direction[axis];
        t_delta[axis] = 1.0 / direction[axis];
      } else if (direction[axis] < 0.0) {
        step[axis] = -1;
        next_boundary[axis] = (cell[axis] - origin_scaled[axis]) / direction[axis];
        t_delta[axis] = -1.0 / direction[axis];
      } else {
        step[axis] = 0;
        next_boundary[axis] = std::numeric_limits<double>::infinity();
        t_delta[axis] = std::numeric_limits<double>::infinity();
      }
    }
    // `remaining` counts the boundary crossings to the last cell; rounding can make the
    // traversal pick a neighbouring path, never a longer one.
    for (; remaining > 0; --remaining) {
      update(cell, log_odds_miss_);
      int axis = 0;
      for (int other = 1; other < Dim; ++other) {
        if (next_boundary[other] < next_boundary[axis]) axis = other;
      }
      cell[axis] += step[axis];
      next_boundary[axis] += t_delta[axis];
    }
    if (cut || cell != last) update(cell, log_odds_miss_);
  }
  return ok_status();
}

template <int Dim>
float OccupancyGrid<Dim>::log_odds(const Index& cell) const {
  const Index block_index = Storage::block_of(cell);
  const auto* block = storage_->find(block_index);
  return block == nullptr ? 0.0f : block->log_odds[Storage::offset_in_block(cell, block_index)];
}

template <int Dim>
bool OccupancyGrid<Dim>::observed(const Index& cell) const {
  const Index block_index = Storage::block_of(cell);
  const auto* block = storage_->find(block_index);
  return block != nullptr && block->stamp[Storage::offset_in_block(cell, block_index)] != 0;
}

template <int Dim>
double OccupancyGrid<Dim>::probability(const Index& cell) const {
  return observed(cell) ? log_odds_to_probability(log_odds(cell)) : 0.5;
}

template <int Dim>
double OccupancyGrid<Dim>::probability(const Point& point) const {
  return probability(cell_index(point));
}

template <int Dim>
CellState OccupancyGrid<Dim>::state(const Index& cell) const {
  if (!observed(cell)) return CellState::kUnknown;
  const double p = probability(cell);
  if (p > config_.occupied_threshold) return CellState::kOccupied;
  if (p < config_.free_threshold) return CellState::kFree;
  return CellState::kUnknown;
}

template <int Dim>
CellState OccupancyGrid<Dim>::state(const Point& point) const {
  return state(cell_index(point));
}

template <int Dim>
void OccupancyGrid<Dim>::for_each_observed(const std::function<void(const Index&, float)>& visit) const {
  for (const auto& [key, block] : storage_->blocks) {
    const Index block_index = Storage::block_from_key(key);
    for (int offset = 0; offset < Storage::kBlockCells; ++offset) {
      if (block->stamp[offset] != 0) visit(Storage::cell_in_block(block_index, offset), block->log_odds[offset]);
    }
  }
}

template <int Dim>
std::size_t OccupancyGrid<Dim>::observed_cell_count() const {
  std::size_t count = 0;
  for (const auto& [key, block] : storage_->blocks) {
    count += static_cast<std::size_t>(std::count_if(block->stamp.begin(), block->stamp.end(), [](uint32_t s) { return s != 0; }));
  }
  return count;
}

template <int Dim>
std::optional<std::pair<typename OccupancyGrid<Dim>::Index, typename OccupancyGrid<Dim>::Index>>
OccupancyGrid<Dim>::observed_bounds() const {
  std::optional<std::pair<Index, Index>> bounds;
  for_each_observed([&](const Index& cell, float) {
    if (!bounds) {
      bounds.emplace(cell, cell);
    } else {
      bounds->first = bounds->first.cwiseMin(cell);
      bounds->second = bounds->second.cwiseMax(cell);
    }
  });
  return bounds;
}

template <int Dim>
std::size_t OccupancyGrid<Dim>::memory_bytes() const {
  // Each node of the hash map: key, pointer, next pointer and the cached hash, plus buckets.
  const std::size_t per_entry = sizeof(uint64_t) + 3 * sizeof(void*);
  return storage_->blocks.size() * (sizeof(typename Storage::Block) + per_entry) +
         storage_->blocks.bucket_count() * sizeof(void*);
}

template <int Dim>
msgs::OccupancyGridLayer OccupancyGrid<Dim>::to_layer() const {
  msgs::OccupancyGridLayer layer;
  layer.resolution = config_.resolution;
  layer.size_x = 0;
  layer.size_y = 0;
  layer.size_z = Dim == 2 ? 1 : 0;
  const auto bounds = observed_bounds();
  if (!bounds) return layer;
  const Index size = bounds->second - bounds->first + Index::Ones();
  layer.size_x = static_cast<uint32_t>(size[0]);
  layer.size_y = static_cast<uint32_t>(size[1]);
  layer.size_z = Dim == 2 ? 1 : static_cast<uint32_t>(size[Dim - 1]);
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  origin.head<Dim>() = bounds->first.template cast<double>() * config_.resolution;
  layer.origin.position = origin;
  layer.origin.orientation = Eigen::Quaterniond::Identity();
  layer.occupancy.assign(static_cast<std::size_t>(layer.size_x) * layer.size_y * layer.size_z, 0.5f);
  for_each_observed([&](const Index& cell, float cell_log_odds) {
    const Index local = cell - bounds->first;
    std::size_t linear = static_cast<std::size_t>(local[Dim - 1]);
    for (int axis = Dim - 2; axis >= 0; --axis) linear = linear * static_cast<std::size_t>(size[axis]) + static_cast<std::size_t>(local[axis]);
    layer.occupancy[linear] = static_cast<float>(log_odds_to_probability(cell_log_odds));
  });
  return layer;
}

template <int Dim>
Result<OccupancyGrid<Dim>> OccupancyGrid<Dim>::from_layer(const msgs::OccupancyGridLayer& layer, OccupancyConfig config) {
  HANZO_RETURN_IF_ERROR(validate_layer(layer));
  if (Dim == 2 && layer.size_z != 1) {
    return Error{fmt::format("occupancy layer: size_z is {}, a 2D grid needs 1", layer.size_z), "occupancy.size_z"};
  }
  config.resolution = layer.resolution;
  HANZO_RETURN_IF_ERROR(config.validate());
  OccupancyGrid grid(config);
  Eigen::Vector3i first_cell;
  HANZO_ASSIGN_OR_RETURN(first_cell, occupancy_layer_first_cell(layer));
  const Index first = first_cell.head<Dim>();
  Index size;
  size[0] = static_cast<int>(layer.size_x);
  size[1] = static_cast<int>(layer.size_y);
  if constexpr (Dim == 3) size[2] = static_cast<int>(layer.size_z);
  if (((first + size).array().abs() >= kIndexLimit).any()) {
    return Error{"occupancy layer: the grid extends past the supported index range", "occupancy.size_x"};
  }
  std::size_t linear = 0;
  Index local = Index::Zero();
  for (; linear < layer.occupancy.size(); ++linear) {
    const float probability_value = layer.occupancy[linear];
    if (probability_value != 0.5f) {
      const Index cell = first + local;
      const Index block_index = Storage::block_of(cell);
      auto& block = grid.storage_->find_or_create(block_index);
      const int offset = Storage::offset_in_block(cell, block_index);
      const double clamped = std::clamp(static_cast<double>(probability_value), config.probability_min, config.probability_max);
      block.log_odds[offset] = static_cast<float>(probability_to_log_odds(clamped));
      block.stamp[offset] = kImportedStamp;
    }
    for (int axis = 0; axis < Dim; ++axis) {
      if (++local[axis] < size[axis]) break;
      local[axis] = 0;
    }
  }
  return grid;
}

template class OccupancyGrid<2>;
template class OccupancyGrid<3>;

}  // namespace hanzo::fusion::maps
