#pragma once
// Multiresolution hash encoding (Mueller et al., "Instant Neural Graphics Primitives", SIGGRAPH
// 2022, Sec. 3): `levels` grids whose resolutions grow geometrically from base_resolution to
// finest_resolution (eq. 2-3); at each level a point's 8 surrounding vertices index a table of
// `features_per_level` floats (densely while the level's vertices fit the table, else by the
// spatial hash of eq. 4, 1 XOR x + 2654435761 y + 805459861 z modulo the table size), and the
// level's features are the trilinear blend of the 8 entries. The outputs of all levels are
// concatenated: levels x features_per_level floats per point.
//
// Positions are in the unit cube [0, 1]^3 (points outside are clamped to it). The parameters are
// one float array owned by the caller (parameter_count() floats, level after level), so that any
// optimizer can move them. forward() runs over the points in parallel; backward() accumulates
// into a gradient array of the parameters' size, each level on one thread, so that the sums do
// not depend on the thread schedule.

#include <cstddef>
#include <cstdint>
#include <vector>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::neural {

struct HashGridConfig {
  int levels = 16;              ///< L
  int features_per_level = 2;   ///< F
  int log2_table_size = 19;     ///< T = 2^19 entries per level at most
  int base_resolution = 16;     ///< N_min, vertices per unit at the coarsest level
  int finest_resolution = 2048;  ///< N_max at the finest level
};

Status validate(const HashGridConfig& config);

class HashGrid {
 public:
  explicit HashGrid(const HashGridConfig& config);  ///< the config must be valid

  int output_width() const { return config_.levels * config_.features_per_level; }
  std::size_t parameter_count() const { return level_offset_.back() * static_cast<std::size_t>(config_.features_per_level); }
  const HashGridConfig& config() const { return config_; }

  /// features[i * output_width() + level * F + f] for each of `count` points (x, y, z at positions[3 i]).
  void forward(const float* parameters, const float* positions, std::size_t count, float* features) const;
  /// gradient[parameter] += sum over points of dL/dfeatures * d features / d parameter.
  void backward(const float* positions, std::size_t count, const float* feature_gradient, float* gradient) const;

 private:
  struct Corners {
    std::size_t index[8];  ///< entries (not floats) from the start of the parameters
    float weight[8];
  };
  void corners(int level, const float* position, Corners& out) const;

  HashGridConfig config_;
  std::vector<double> scale_;            ///< per level: vertices per unit - 1
  std::vector<uint32_t> resolution_;     ///< per level: vertices along an axis
  std::vector<std::size_t> level_offset_;  ///< first entry of each level; back(): entries in all
};

}  // namespace hanzo::fusion::neural
