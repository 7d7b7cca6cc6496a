#pragma once
// Where a ground robot can drive, from a map's points: an elevation map of the ground per cell of
// a 2D grid and the slope and step filters of elevation-map traversability (Fankhauser et al.,
// "Robot-Centric Elevation Mapping", 2014; the slope / step / clearance tests of grid_map's
// traversability filters).
//
// Frames and units: points and normals in the world frame (z up), the grid's cells as the
// OccupancyGridLayer places them (origin = T_world_grid, x/y cells of `resolution`), metres.
//
// Per cell (its column of points):
//   ground:  the points whose normal is within ground_max_tilt_deg of vertical (surfaces a
//            wheel could stand on, ramps included) are ground candidates; from the 10th
//            percentile of their heights (the lowest surface, robust to a few stray points
//            below it), the ground height is the median of the candidates within max_step_m
//            of it. No candidate: the ground is unknown (NaN);
//   slope:   the plane z = a x + b y + c fitted through the ground heights of the cell and its
//            eight neighbours (at least three cells, not on a line); slope = atan(|(a, b)|);
//            NaN when the neighbourhood cannot fix a plane;
//   step:    the largest height difference to a neighbour's ground, or between the 10th and
//            90th percentiles of the cell's own candidates (two levels within one cell: the
//            edge of a kerb, whose corner normals blur the two surfaces);
//   blocked: a point of the column lies more than max_step_m and at most robot_height_m above
//            the ground (something the robot would hit: a box, a wall, a table's legs).
// A cell is traversable when its ground is known, it is not blocked, its step is at most
// max_step_m and its slope (when known) at most max_slope_deg.
//
// Failure cases: ground under an overhang lower than robot_height_m is blocked (a table);
// glass and other surfaces the LiDAR does not return leave cells unknown; a grid that is not 2D
// gives no cells.

#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct TraversabilityConfig {
  double max_slope_deg = 20.0;        ///< steeper ground is not traversable (a wheeled robot's or a car's limit)
  double max_step_m = 0.10;           ///< a higher jump to a neighbouring cell's ground is a step it cannot climb (a kerb)
  double robot_height_m = 2.0;        ///< points up to this above the ground block the cell
  double ground_max_tilt_deg = 45.0;  ///< ground candidates: normals this close to vertical (steeper ramps are walls)

  /// Checks every field; the error names the first one out of range.
  Status validate() const;
};

struct GroundCell {
  float height = std::numeric_limits<float>::quiet_NaN();     ///< m, world z; NaN: no ground seen
  float slope_deg = std::numeric_limits<float>::quiet_NaN();  ///< NaN: no plane through the neighbourhood
  float step_m = 0.0F;
  bool blocked = false;

  bool has_ground() const { return std::isfinite(height); }
  bool traversable(const TraversabilityConfig& config) const {
    return has_ground() && !blocked && step_m <= config.max_step_m && !(slope_deg > config.max_slope_deg);
  }
};

/// One GroundCell per cell of `grid` (size_x * size_y, row-major, y rows), empty for a grid with
/// size_z != 1. `normals` holds one unit normal per point (cloud/local_geometry.hpp).
std::vector<GroundCell> ground_cells(const msgs::OccupancyGridLayer& grid, const std::vector<Eigen::Vector3f>& points,
                                     const std::vector<Eigen::Vector3f>& normals, const TraversabilityConfig& config);

}  // namespace hanzo::fusion::maps
