#pragma once
// What changed between two versions of a map (spec: "changes in the physical space ... are
// detected by comparing new sensor data against the existing map").
//
// Occupancy: both grids must have the same resolution, the same dimension (2D or 3D) and
// origins on the same cell lattice; every cell of the union of their extents is classified in
// each (occupied / free / unknown by the thresholds) and the transitions are counted. The cells
// that flipped between occupied and free are listed (world cell indices: cell i covers
// [i, i + 1) * resolution).
//
// Points: both point layers are voxelized at one voxel size; a voxel of `after` with no voxel
// of `before` in its 3 x 3 x 3 neighbourhood is added, and the other way round removed. The
// neighbourhood absorbs points that moved across a voxel boundary by noise alone.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct MapDiffConfig {
  double occupied_threshold = 0.65;
  double free_threshold = 0.196;
  /// Voxel edge for comparing points (m); 0: the larger voxel_size of the two layers, or 0.1
  /// when neither is voxelized.
  double point_voxel_size = 0.0;
};

struct OccupancyDiff {
  double resolution = 0.0;
  bool three_dimensional = false;
  std::size_t cells_compared = 0;
  std::size_t became_occupied = 0;   ///< free -> occupied: something appeared
  std::size_t became_free = 0;       ///< occupied -> free: something went away
  std::size_t newly_observed = 0;    ///< unknown -> occupied or free
  std::size_t no_longer_observed = 0;  ///< occupied or free -> unknown
  std::vector<Eigen::Vector3i> appeared_cells;  ///< the free -> occupied cells
  std::vector<Eigen::Vector3i> vanished_cells;  ///< the occupied -> free cells
};

struct PointDiff {
  double voxel_size = 0.0;
  std::size_t voxels_before = 0;
  std::size_t voxels_after = 0;
  std::vector<Eigen::Vector3f> added;    ///< voxel centres
  std::vector<Eigen::Vector3f> removed;  ///< voxel centres
};

struct MapDiff {
  std::optional<OccupancyDiff> occupancy;  ///< when both maps have an occupancy layer
  std::optional<PointDiff> points;         ///< when both maps have a point layer
};

/// Fails when the maps share no comparable layer or their grids do not line up (naming why).
Result<MapDiff> diff_maps(const msgs::FusionMap& before, const msgs::FusionMap& after, const MapDiffConfig& config = {});

/// A PNG of an occupancy diff over `after`'s grid (3D flattened): unchanged occupied black,
/// free white, unknown grey, appeared red, vanished green.
Status write_diff_png(const std::string& path, const msgs::OccupancyGridLayer& after, const OccupancyDiff& diff);

}  // namespace hanzo::fusion::maps
