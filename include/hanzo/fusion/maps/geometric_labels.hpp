#pragma once
// Geometric semantic labels for a map's points, from geometry alone (no camera, no model):
// every point's surface normal (the smallest-eigenvalue direction of its k nearest neighbours,
// cloud/local_geometry.hpp) and its height above the floor.
//
// Frames and units: the layer's world frame with z up (gravity), metres.
//
// 1. Horizontal points: normal within horizontal_max_tilt_deg of vertical.
// 2. The floor height: the z histogram (histogram_bin_m) of the horizontal points; the floor is
//    the lowest bin holding at least floor_min_share of the fullest bin's points (the largest
//    low horizontal surface: table and box tops are smaller, ceilings higher).
// 3. Each point: kFloor when horizontal and within floor_tolerance_m of the floor height;
//    kWall when its normal is within vertical_max_tilt_deg of horizontal (a vertical surface,
//    whatever its height); kObstacle when it lies between floor_tolerance_m and robot_height_m
//    above the floor; kUnknown otherwise (above the robot or below the floor). A layer of fewer
//    than 3 points is all kUnknown.
//
// Failure cases: without horizontal points no floor is found (floor_height empty): points are
// then kWall or kUnknown. One floor per layer: several storeys or ramps are labelled against the
// floor found. A layer whose points are not in a z-up world gets meaningless labels.

#include <array>
#include <cstddef>
#include <optional>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/maps/traversability.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct GeometricLabelConfig {
  int normal_neighbours = 10;             ///< k nearest points (the point included) for each normal
  double horizontal_max_tilt_deg = 20.0;  ///< a normal this close to vertical: a horizontal surface
  double vertical_max_tilt_deg = 20.0;    ///< a normal this close to horizontal: a wall
  double floor_tolerance_m = 0.15;        ///< floor points within this of the floor height
  double robot_height_m = 2.0;            ///< obstacles up to this above the floor
  double histogram_bin_m = 0.05;          ///< floor-height histogram bin
  double floor_min_share = 0.5;           ///< of the fullest bin, for the lowest bin to be the floor
  TraversabilityConfig traversability;    ///< the 2D grid's traversable cells (label_grid)

  /// Checks every field; the error names the first one out of range.
  Status validate() const;
};

struct GeometricLabelSummary {
  std::optional<double> floor_height;  ///< m (world z); empty when no horizontal surface was found
  std::array<std::size_t, 5> counts{};  ///< points per msgs::SemanticLabel value
};

/// Fills layer.labels (one per point, replacing any there) and, when `normals` is given, the
/// points' unit normals into it. Fails on an invalid config only.
Result<GeometricLabelSummary> label_points(msgs::PointLayer& layer, const GeometricLabelConfig& config = {},
                                           std::vector<Eigen::Vector3f>* normals = nullptr);

/// A 2D occupancy grid's labels (grid.size_z == 1; a 3D grid is left unlabelled), one per cell:
///   occupied (P(occupied) >= occupied_threshold): kWall or kObstacle by the majority of
///     `points`' labels in its column (kWall on a tie; kObstacle when none fall in it);
///   otherwise, where `points` show the cell's ground (traversability.hpp, with their unit
///     `normals`): kTraversable when its slope, step and clearance allow, else kObstacle;
///   otherwise a free cell (P <= free_threshold: rays crossed it in the robot's height band):
///     kTraversable (a map's points are sparser than its grid: most free cells hold no ground
///     point; a drop in the floor there goes unseen);
///   otherwise kUnknown (never observed, or undecided).
/// Replaces grid.labels.
void label_grid(msgs::OccupancyGridLayer& grid, const msgs::PointLayer& points, const std::vector<Eigen::Vector3f>& normals,
                double occupied_threshold, double free_threshold, const TraversabilityConfig& traversability = {});

/// A 3D occupancy grid's labels (grid.size_z > 1; a 2D grid is left unlabelled), one per voxel:
/// an occupied voxel (P >= occupied_threshold) takes the most frequent label of `points` inside
/// it (the first in label order on a tie; kObstacle when none falls in it); every other voxel
/// kUnknown. Replaces grid.labels.
void label_voxels(msgs::OccupancyGridLayer& grid, const msgs::PointLayer& points, double occupied_threshold);

/// A mesh's vertex labels: the label of the nearest of `points` within max_distance (m), else
/// kUnknown; none when the points carry no labels. Replaces mesh.vertex_labels.
void label_mesh(msgs::MeshLayer& mesh, const msgs::PointLayer& points, double max_distance);

/// "unknown", "floor", "wall", "obstacle", "traversable".
const char* semantic_label_name(msgs::SemanticLabel label);

/// The rules of step 3 for one point, given its unit normal, its z and the floor height.
msgs::SemanticLabel geometric_label(const Eigen::Vector3f& normal, double z, std::optional<double> floor_height, const GeometricLabelConfig& config);

}  // namespace hanzo::fusion::maps
