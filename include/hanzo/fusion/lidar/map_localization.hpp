#pragma once
// Localization of a LiDAR sweep in a known point map: where is the sensor in the map's frame,
// with no prior at all ("kidnapped robot", a restart in a mapped warehouse) or near a guess.
//
// Two stages:
//  1. Global 2D search (Hess et al., "Real-Time Loop Closure in 2D LIDAR SLAM", ICRA 2016,
//     sec. V, Algorithm 3: branch and bound over a stack of precomputed max-grids). The map and
//     the sweep are cut to a slice between slice_min_height and slice_max_height above their
//     local ground (the map's ground per ground_cell column, the sweep's below the sensor), so
//     slopes and sensor mounting heights cancel; the map slice is blurred into a likelihood grid
//     (Olson 2009, as correlative_scan_matcher.hpp) and every heading x every cell of the
//     searched area is bounded level by level: a node at level k covers 2^k x 2^k translations
//     and scores the mean of the level-k max-grid, an upper bound of all of them; nodes whose
//     bound cannot beat the best full-resolution score found are pruned. The result is the
//     exhaustive search's optimum.
//  2. 3D refinement and verification of each of the best `candidates` distinct 2D poses:
//     point-to-surface registration of the sweep against the map (surface_registration.hpp)
//     at two resolutions from the 2D pose (height from the map's
//     ground + the sensor's height above its ground); accepted when it converges with an inlier
//     RMSE <= max_rmse, >= min_inlier_fraction of the points matched, a non-degenerate
//     geometry, and free space that agrees: the sweep must not see through more than
//     max_seen_through_fraction of the map points in its view (a subset of the map, such as one
//     wall corner, registers well almost anywhere; what lies in front of its returns tells).
//     The answer is the verified pose with the lowest RMSE; another distinct place (> 1 m away)
//     that verifies with a comparable fit (RMSE <= 2 x the best's + 2 cm) is an ambiguity (the
//     same view from several places, e.g. repeated aisles): refused with the places named,
//     never guessed.
//
// Frames: the map is gravity-aligned (z up), as the maps of Sessions are; points of the query
// are in the sensor frame, R_up_sensor is the sensor's orientation in any z-up frame (its roll
// and pitch are used, its yaw is not). Units: meters, radians.
//
// Failure cases (an Error naming which): too few map or sweep points in the slice, a searched
// area over max_grid_cells, non-finite input, no pose scoring min_score in 2D, no candidate
// that verifies in 3D (the best one's numbers in the message), or an ambiguity.

#include <optional>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/cloud/voxel_hash_map.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/lidar/lidar_odometry.hpp"

namespace hanzo::fusion::lidar {

struct MapLocalizerConfig {
  double grid_resolution = 0.2;        ///< m, cell of the 2D likelihood grid and translation step
  double likelihood_sigma = 0.2;       ///< m, blur of the map slice (scaled with the cell)
  /// A searched area of more than this many cells is searched at a coarser cell (up to
  /// max_grid_resolution): the search costs cells x headings, and the 3D refinement pulls a
  /// pose in from a metre off. 1 M cells = 200 x 200 m at 0.2 m.
  std::size_t search_cells = 1'000'000;
  double max_grid_resolution = 0.5;    ///< m
  double slice_min_height = 0.3;       ///< m above the local ground
  double slice_max_height = 3.0;       ///< m above the local ground
  double ground_cell = 2.0;            ///< m, columns of the map's ground height (lowest point)
  double query_max_range = 40.0;       ///< m, sweep points farther away are not used in 2D
  double query_point_spacing = 0.3;    ///< m, the sweep's slice is thinned to this in 2D
  std::size_t max_query_points = 1000; ///< and to at most this many (every k-th)
  int branch_and_bound_depth = 7;      ///< levels of max-grids: top nodes cover 2^7 = 128 cells
  std::size_t max_grid_cells = 6'000'000;  ///< cells of the searched grid (memory: depth + 1 floats each)
  double min_score = 0.4;              ///< mean likelihood of the 2D match, in [0, 1]
  double max_rmse = 0.15;              ///< m, 3D inlier RMSE accepted
  double min_inlier_fraction = 0.3;    ///< of the sweep's registration points matched in 3D
  /// The best distinct 2D poses (1 m or 10 deg apart) verified in 3D: repetitive places (aisles
  /// of racks) score alike in 2D; the 3D checks tell them apart, or the answer is "ambiguous".
  std::size_t candidates = 5;
  /// Only 2D poses scoring at least this fraction of the best are candidates (rivals); lower
  /// ones are pruned, which keeps the search fast on large outdoor maps.
  double candidate_score_ratio = 0.75;
  std::size_t min_slice_points = 50;   ///< in the map's and in the sweep's slice
  /// Free-space check: of the map points within query_max_range that the sweep has a return
  /// near or beyond (same direction), at most this fraction may lie in front of the return
  /// (the sweep saw through them: the pose or the map is wrong).
  double max_seen_through_fraction = 0.25;

  Status validate() const;
};

/// Where to search: everywhere in the map (no guess), or a window around a guess.
struct MapLocalizationQuery {
  std::optional<SE3> T_map_sensor_guess;
  double linear_window = 5.0;    ///< m, +- around the guess's position (with a guess)
  double angular_window = 0.5;   ///< rad, +- around the guess's heading (with a guess)
};

struct MapLocalization {
  SE3 T_map_sensor;
  double score = 0.0;              ///< mean likelihood of the 2D match
  double inlier_rmse = 0.0;        ///< m, 3D refinement
  double inlier_fraction = 0.0;    ///< of the registration points
  double seen_through_fraction = 0.0;  ///< free-space check (MapLocalizerConfig)
  std::size_t candidate_rank = 0;  ///< which of the best 2D poses verified (0: the best)
  bool global = false;             ///< searched the whole map (no guess)
  std::size_t nodes_evaluated = 0; ///< branch and bound nodes scored
  std::size_t headings = 0;        ///< headings searched
  double seconds = 0.0;            ///< time of localize()
};

class MapLocalizer {
 public:
  /// Prepares `map_points` (map frame) for queries; `odometry` gives the registration settings
  /// (source voxel, map voxels, surface registration) of the 3D refinement.
  static Result<MapLocalizer> create(std::vector<Eigen::Vector3f> map_points, const MapLocalizerConfig& config = {},
                                     const LidarOdometryConfig& odometry = {});

  /// The sensor's pose in the map for a sweep (`points` in the sensor frame, deskewed).
  Result<MapLocalization> localize(const std::vector<Eigen::Vector3f>& points, const SO3& R_up_sensor,
                                   const MapLocalizationQuery& query = {}) const;

  std::size_t map_points() const { return points_.size(); }

 private:
  MapLocalizer(MapLocalizerConfig config, LidarOdometryConfig odometry) : config_(config), odometry_(std::move(odometry)) {}
  /// Height of the map's ground under (x, y): the lowest point of the nearest non-empty column.
  std::optional<double> ground_height(double x, double y) const;
  /// 3D refinement and checks of one candidate pose (`sweep`: all points, `source`: the
  /// registration points, both in the sensor frame).
  Result<MapLocalization> verify(const std::vector<Eigen::Vector3f>& sweep, const std::vector<Eigen::Vector3f>& source,
                                 const SE3& guess) const;

  MapLocalizerConfig config_;
  LidarOdometryConfig odometry_;
  std::vector<Eigen::Vector3f> points_;
  std::vector<Eigen::Vector2f> slice_;  ///< map points in the height slice, (x, y)
  std::vector<Eigen::Vector3f> structure_;  ///< map points above the ground (free-space check)
  Eigen::Vector2d min_corner_ = Eigen::Vector2d::Zero(), max_corner_ = Eigen::Vector2d::Zero();  ///< of the slice
  // Ground columns.
  Eigen::Vector2d ground_origin_ = Eigen::Vector2d::Zero();
  int ground_width_ = 0, ground_height_cells_ = 0;
  std::vector<float> ground_;  ///< lowest z per column, NaN when empty
  // 3D refinement targets: coarse (3x voxels) and fine (the odometry's map voxels).
  std::optional<cloud::VoxelHashMap> coarse_, fine_;
};

}  // namespace hanzo::fusion::lidar
