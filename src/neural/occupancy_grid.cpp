#include "hanzo/fusion/neural/occupancy_grid.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace hanzo::fusion::neural {

OccupancyGrid::OccupancyGrid(const OccupancyGridConfig& config) : config_(config) {
  const std::size_t cells = static_cast<std::size_t>(config.resolution) * static_cast<std::size_t>(config.resolution) * static_cast<std::size_t>(config.resolution);
  value_.assign(cells, 0.0f);
  seen_.assign(cells, 1);
  occupied_.assign(cells, 1);
}

std::size_t OccupancyGrid::cell_of(const Eigen::Vector3f& position) const {
  const int n = config_.resolution;
  std::size_t index = 0;
  for (int axis = 2; axis >= 0; --axis) {
    const int i = std::clamp(static_cast<int>(position[axis] * static_cast<float>(n)), 0, n - 1);
    index = index * static_cast<std::size_t>(n) + static_cast<std::size_t>(i);
  }
  return index;
}

bool OccupancyGrid::occupied(const Eigen::Vector3f& position) const {
  if ((position.array() < 0.0f).any() || (position.array() > 1.0f).any()) return false;
  return occupied_[cell_of(position)] != 0;
}

std::size_t OccupancyGrid::occupied_count() const { return static_cast<std::size_t>(std::count(occupied_.begin(), occupied_.end(), uint8_t{1})); }

void OccupancyGrid::set_seen(const std::vector<uint8_t>& seen) {
  seen_ = seen;
  for (std::size_t i = 0; i < occupied_.size(); ++i) occupied_[i] = seen_[i] != 0 ? occupied_[i] : 0;
}

void OccupancyGrid::restore(std::vector<float> values, std::vector<uint8_t> seen) {
  value_ = std::move(values);
  seen_ = std::move(seen);
  threshold();
}

void OccupancyGrid::threshold() {
  double sum = 0.0;
  std::size_t count = 0;
  for (std::size_t i = 0; i < value_.size(); ++i) {
    if (seen_[i] == 0) continue;
    sum += value_[i];
    ++count;
  }
  const float mean = count > 0 ? static_cast<float>(sum / static_cast<double>(count)) : 0.0f;
  const float limit = std::min(mean, config_.min_optical_thickness);
  for (std::size_t i = 0; i < value_.size(); ++i) occupied_[i] = seen_[i] != 0 && value_[i] > limit ? 1 : 0;
}

void OccupancyGrid::update(const DensityFunction& density, float step, bool all, double share, std::mt19937_64& random) {
  std::vector<uint32_t> chosen;
  if (all) {
    for (std::size_t i = 0; i < value_.size(); ++i) {
      if (seen_[i] != 0) chosen.push_back(static_cast<uint32_t>(i));
    }
  } else {
    const auto draws = static_cast<std::size_t>(share * static_cast<double>(value_.size()));
    std::uniform_int_distribution<uint32_t> any_cell(0, static_cast<uint32_t>(value_.size() - 1));
    for (std::size_t k = 0; k < draws; ++k) {
      const uint32_t cell = any_cell(random);
      if (seen_[cell] != 0) chosen.push_back(cell);
    }
    std::vector<uint32_t> occupied_cells;
    for (std::size_t i = 0; i < occupied_.size(); ++i) {
      if (occupied_[i] != 0) occupied_cells.push_back(static_cast<uint32_t>(i));
    }
    if (!occupied_cells.empty()) {
      std::uniform_int_distribution<std::size_t> any_occupied(0, occupied_cells.size() - 1);
      for (std::size_t k = 0; k < draws; ++k) chosen.push_back(occupied_cells[any_occupied(random)]);
    }
  }
  const int n = config_.resolution;
  std::uniform_real_distribution<float> jitter(0.0f, 1.0f);
  std::vector<float> positions(3 * chosen.size());
  for (std::size_t k = 0; k < chosen.size(); ++k) {
    std::size_t cell = chosen[k];
    for (int axis = 0; axis < 3; ++axis) {
      positions[3 * k + static_cast<std::size_t>(axis)] = (static_cast<float>(cell % static_cast<std::size_t>(n)) + jitter(random)) / static_cast<float>(n);
      cell /= static_cast<std::size_t>(n);
    }
  }
  std::vector<float> sigma(chosen.size());
  if (!chosen.empty()) density(positions.data(), chosen.size(), sigma.data());
  std::vector<float> fresh(value_.size(), -1.0f);  // a cell drawn twice keeps its larger value
  for (std::size_t k = 0; k < chosen.size(); ++k) fresh[chosen[k]] = std::max(fresh[chosen[k]], sigma[k] * step);
  for (std::size_t i = 0; i < value_.size(); ++i) {
    if (fresh[i] >= 0.0f) value_[i] = std::max(value_[i] * config_.decay, fresh[i]);
  }
  threshold();
}

bool OccupancyGrid::intersect(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float& t_enter, float& t_exit) {
  t_enter = 0.0f;
  t_exit = std::numeric_limits<float>::infinity();
  for (int axis = 0; axis < 3; ++axis) {
    if (std::abs(direction[axis]) < 1e-12f) {
      if (origin[axis] < 0.0f || origin[axis] > 1.0f) return false;
      continue;
    }
    float a = (0.0f - origin[axis]) / direction[axis];
    float b = (1.0f - origin[axis]) / direction[axis];
    if (a > b) std::swap(a, b);
    t_enter = std::max(t_enter, a);
    t_exit = std::min(t_exit, b);
  }
  return t_enter < t_exit;
}

int OccupancyGrid::march(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float step, float t_end, int max_samples, float& t,
                         RaySamples& samples) const {
  const auto n = static_cast<float>(config_.resolution);
  int added = 0;
  while (t < t_end && added < max_samples) {
    const Eigen::Vector3f p = origin + t * direction;
    const std::size_t cell = cell_of(p);
    if (occupied_[cell] != 0) {
      samples.t.push_back(t);
      samples.dt.push_back(step);
      samples.position.insert(samples.position.end(), {p.x(), p.y(), p.z()});
      ++added;
      t += step;
      continue;
    }
    // Jump to the first lattice step past the cell's exit.
    float t_out = std::numeric_limits<float>::infinity();
    for (int axis = 0; axis < 3; ++axis) {
      if (direction[axis] == 0.0f) continue;
      const float index = std::clamp(std::floor(p[axis] * n), 0.0f, n - 1.0f);
      const float boundary = (direction[axis] > 0.0f ? index + 1.0f : index) / n;
      t_out = std::min(t_out, (boundary - origin[axis]) / direction[axis]);
    }
    t += std::max(1.0f, std::ceil((t_out - t) / step)) * step;
  }
  samples.ray_begin.push_back(static_cast<uint32_t>(samples.t.size()));
  return added;
}

}  // namespace hanzo::fusion::neural
