#pragma once
// Occupancy grid over the unit cube for skipping empty space while marching rays through a
// neural field (instant-ngp, Mueller et al. 2022, Appendix E.2): per cell the field's optical
// thickness at a step (density x step length), kept as a decaying maximum over updates
// (value = max(decay x value, new)); a cell is occupied while its value exceeds the smaller of
// `min_optical_thickness` and the mean over the cells. Cells no training camera sees are never
// occupied (they hold no information, only floaters).
//
// Rays are marched at a fixed step from where they enter the cube: samples in occupied cells
// are kept, empty cells are jumped over to the next step past their exit, so that the samples of
// a ray stay on one lattice t_0 + k dt whatever the grid holds.

#include <cstdint>
#include <functional>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/neural/volume_rendering.hpp"

namespace hanzo::fusion::neural {

struct OccupancyGridConfig {
  int resolution = 128;                ///< cells along each axis of the unit cube
  float min_optical_thickness = 0.01f;  ///< a cell's value above which it always counts occupied
  float decay = 0.95f;                 ///< per update
};

/// Densities of the field at points of the unit cube (x, y, z each), `count` of them.
using DensityFunction = std::function<void(const float* positions, std::size_t count, float* density)>;

class OccupancyGrid {
 public:
  explicit OccupancyGrid(const OccupancyGridConfig& config = {});

  int resolution() const { return config_.resolution; }
  std::size_t cells() const { return value_.size(); }
  bool occupied_cell(std::size_t cell) const { return occupied_[cell] != 0; }
  bool occupied(const Eigen::Vector3f& position) const;  ///< outside the cube: false
  std::size_t occupied_count() const;

  /// Marks which cells are seen (false: never occupied); every cell starts seen and occupied.
  void set_seen(const std::vector<uint8_t>& seen);
  const std::vector<uint8_t>& seen() const { return seen_; }
  const std::vector<float>& values() const { return value_; }
  const std::vector<uint8_t>& occupancy() const { return occupied_; }
  /// Restores a saved state (sizes must match cells()).
  void restore(std::vector<float> values, std::vector<uint8_t> seen);

  /// Evaluates `density` at a random point of the chosen cells (every seen cell when `all`, else
  /// `share` of the cells at random plus as many occupied ones), with `step` the marching step,
  /// and re-thresholds the grid.
  void update(const DensityFunction& density, float step, bool all, double share, std::mt19937_64& random);

  /// Entry and exit of the ray through the unit cube (false when it misses or starts past it).
  static bool intersect(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float& t_enter, float& t_exit);

  /// Appends to `samples` the samples from `t` (advanced past them) up to `t_end` in occupied
  /// cells, at most max_samples; positions origin + t direction. Returns how many were added.
  int march(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float step, float t_end, int max_samples, float& t,
            RaySamples& samples) const;

 private:
  std::size_t cell_of(const Eigen::Vector3f& position) const;
  void threshold();

  OccupancyGridConfig config_;
  std::vector<float> value_;
  std::vector<uint8_t> seen_, occupied_;
};

}  // namespace hanzo::fusion::neural
