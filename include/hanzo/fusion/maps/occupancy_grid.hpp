#pragma once
// Occupancy grids in 2D and 3D (spec, "Map Representations / Occupancy Grid"): each cell holds
// the log-odds of being occupied, updated by ray casting from the sensor origin: cells a ray
// passes through are observed free, the cell holding its end point is observed occupied
// (Thrun, Burgard, Fox, "Probabilistic Robotics", 2005, table 9.1 and eq. 9.7; the clamped
// update of OctoMap, Hornung et al. 2013, eq. 3-4).
//
// Frames and units: cells are axis-aligned in the world frame; cell i covers
// [i * resolution, (i + 1) * resolution) on each axis (meters). A 2D grid lies in the world XY
// plane. Grids have no fixed bounds: storage is allocated in blocks (32 x 32 cells in 2D,
// 8 x 8 x 8 in 3D) as rays reach new space, so memory follows what was observed.
//
// One scan updates each cell at most once, and an end point wins over a ray passing through
// the same cell (a wall is not erased by the many nearly-parallel rays that graze it).
// Never-observed cells are unknown (probability 0.5).

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct OccupancyConfig {
  /// Cell edge (m). Spec defaults: 0.05 indoor, 0.2 outdoor.
  double resolution = 0.05;
  /// P(occupied) a single end point gives its cell, and a ray passing through gives its cells
  /// (log-odds +1.73 and -0.12). Misses are weak on purpose: rays grazing a wall at a shallow
  /// angle cross its cells without meaning they are free, and with OctoMap's 0.7 / 0.4 they
  /// erase thin walls (the intel lab at 0.05 m keeps 78 % of its scan end points in occupied
  /// cells with 0.7 / 0.4, 96.6 % with these; Cartographer weights misses as weakly, 0.55 / 0.49).
  /// A cell that stops being hit (a person walked away) clears after about 30 scans.
  double probability_hit = 0.85;
  double probability_miss = 0.47;
  /// Clamping bounds of the cell probability, so that a changed world can be relearned
  /// (OctoMap's 0.12 / 0.97).
  double probability_min = 0.12;
  double probability_max = 0.97;
  /// Classification thresholds: above occupied_threshold a cell is occupied, below
  /// free_threshold it is free, otherwise unknown (ROS map_server's occupied_thresh and
  /// free_thresh).
  double occupied_threshold = 0.65;
  double free_threshold = 0.196;
  /// Rays longer than this (m) are cut at it and their end is not marked occupied: a return
  /// that far is too uncertain (and a no-return reading is reported as max range). 0: no limit.
  double max_range = 0.0;

  /// Names the first value out of range (probabilities in (0, 1), hit > 0.5 > miss,
  /// min < 0.5 < max, free < occupied thresholds, positive resolution).
  Status validate() const;
};

enum class CellState : uint8_t { kUnknown, kFree, kOccupied };

/// Occupancy grid over Dim = 2 or 3 world axes.
template <int Dim>
class OccupancyGrid {
 public:
  using Point = Eigen::Matrix<double, Dim, 1>;
  using Index = Eigen::Matrix<int, Dim, 1>;

  /// `config` must pass validate() (use create() for configurations from users).
  explicit OccupancyGrid(const OccupancyConfig& config);
  static Result<OccupancyGrid> create(const OccupancyConfig& config);
  ~OccupancyGrid();
  OccupancyGrid(OccupancyGrid&&) noexcept;
  OccupancyGrid& operator=(OccupancyGrid&&) noexcept;
  OccupancyGrid(const OccupancyGrid& other);
  OccupancyGrid& operator=(const OccupancyGrid& other);

  /// Integrates one scan: rays from `sensor_origin` to every end point (world frame, m).
  /// Fails, changing nothing, when a coordinate is not finite or lies beyond the grid's index
  /// range (about +-1e6 cells per axis).
  Status insert_scan(const Point& sensor_origin, std::span<const Point> end_points);

  /// Probability of occupancy of the cell holding `point` (0.5 when unknown).
  double probability(const Point& point) const;
  double probability(const Index& cell) const;
  CellState state(const Point& point) const;
  CellState state(const Index& cell) const;
  /// Log-odds of the cell (0 when unknown).
  float log_odds(const Index& cell) const;
  bool observed(const Index& cell) const;

  Index cell_index(const Point& point) const;
  Point cell_center(const Index& cell) const;

  /// Smallest and largest observed cell index, when any cell was observed.
  std::optional<std::pair<Index, Index>> observed_bounds() const;
  /// Calls `visit(cell, log_odds)` for every observed cell (block order; not sorted).
  void for_each_observed(const std::function<void(const Index&, float)>& visit) const;
  std::size_t observed_cell_count() const;
  std::size_t scan_count() const { return scan_count_; }
  /// Bytes held by cell storage and the block index.
  std::size_t memory_bytes() const;

  /// The observed bounding box as a dense layer (probability per cell, 0.5 unknown); origin is
  /// the world position of the corner of the first cell, no rotation. Empty grids give a
  /// 0-size layer.
  msgs::OccupancyGridLayer to_layer() const;
  /// A grid holding the layer's probabilities, clamped to the configuration's bounds (cells at
  /// exactly 0.5 are unknown). The layer
  /// must be axis-aligned (identity rotation), have size_z == 1 for Dim 2, and pass the
  /// FusionMap checks; config.resolution is replaced by the layer's.
  static Result<OccupancyGrid> from_layer(const msgs::OccupancyGridLayer& layer, OccupancyConfig config);

  const OccupancyConfig& config() const { return config_; }

 private:
  struct Storage;
  OccupancyConfig config_;
  float log_odds_hit_ = 0.0f;
  float log_odds_miss_ = 0.0f;
  float log_odds_min_ = 0.0f;
  float log_odds_max_ = 0.0f;
  std::size_t scan_count_ = 0;
  std::unique_ptr<Storage> storage_;
};

using OccupancyGrid2D = OccupancyGrid<2>;
using OccupancyGrid3D = OccupancyGrid<3>;

extern template class OccupancyGrid<2>;
extern template class OccupancyGrid<3>;

/// The world cell index of a layer's first cell (its origin divided by its resolution). Fails
/// when the origin is rotated or not a whole number of cells from the world origin: such a
/// grid does not line up with the world-aligned cells of OccupancyGrid.
Result<Eigen::Vector3i> occupancy_layer_first_cell(const msgs::OccupancyGridLayer& layer);

/// log(p / (1 - p)) and its inverse.
double probability_to_log_odds(double probability);
double log_odds_to_probability(double log_odds);

}  // namespace hanzo::fusion::maps
