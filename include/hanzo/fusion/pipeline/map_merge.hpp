#pragma once
// merge_maps(): two sessions' FusionMaps of the same place joined into one, without an initial
// guess: where B lies in A is found by localizing views of B's point layer in A's
// (lidar::MapLocalizer: a global 2D branch-and-bound search, 3D registration, free-space and
// ambiguity checks), then B's points are moved into A's frame and joined with A's.
//
// Views of B: centres on a grid of query_spacing over B's points (most points first), a virtual
// sensor sensor_height above B's ground there; the view holds B's points within query_radius
// that the sensor would see first along their direction (a spherical z-buffer of
// view_resolution), so that it is a sweep to the localizer's free-space check. Each view that
// localizes gives a transform T_a_b; B's place in A is accepted when at least min_agreeing views,
// and min_agreeing_share of those that localized, give transforms within agreement_translation /
// agreement_rotation of each other (then the
// best-fitting of them, lowest 3D RMSE, is B's place), and refused otherwise, with the reason
// ("no view of B localized in A", "views disagree").
//
// The merged map: A's metadata and layers; its points and B's moved points on A's voxel grid
// (one point per voxel, A's first), each point's attributes kept where both maps have them;
// B's other layers (occupancy, mesh, landmarks, LiDAR keyframes, ...) are not moved (listed in
// MapMergeResult::dropped_layers), and A's LiDAR keyframes are left out (the points are no
// longer theirs); provenance holds both maps' inputs. Frames: both maps z up
// (gravity-aligned, as Sessions make them). Failure: a map without points, the refusals above.

#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/lidar/map_localization.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::pipeline {

struct MapMergeConfig {
  double query_spacing = 8.0;      ///< m between view centres
  double query_radius = 25.0;      ///< m, B's points around a centre that form its view
  double sensor_height = 1.5;      ///< m above B's ground at the centre
  double view_resolution = 0.01;   ///< rad, the z-buffer's cell in azimuth and elevation
  std::size_t max_views = 10;      ///< views tried (the centres with the most points)
  std::size_t min_agreeing = 2;    ///< views whose transforms agree
  /// and at least this share of the views that localized: a view of generic structure (a
  /// corner, a wall with pillars) may localize somewhere in another place; many views agreeing
  /// on one transform do not.
  double min_agreeing_share = 0.6;
  double agreement_translation = 0.3;   ///< m
  double agreement_rotation = 0.035;    ///< rad (2 degrees)
  lidar::MapLocalizerConfig localizer;
  lidar::LidarOdometryConfig odometry;  ///< the localizer's 3D registration settings
};

struct MapMergeResult {
  msgs::FusionMap merged;
  SE3 T_a_b;                        ///< B's frame in A's
  std::size_t views = 0;            ///< views of B tried
  std::size_t localized = 0;        ///< of which localized in A
  std::size_t agreeing = 0;         ///< of which agree on T_a_b
  std::size_t points_from_b = 0;    ///< B's points added (in voxels A had not)
  std::vector<std::string> dropped_layers;  ///< B's layers other than points
};

/// The names of the map's layers other than points ("occupancy", "tsdf", ..., "lidar_keyframes").
std::vector<std::string> layers_besides_points(const msgs::FusionMap& map);

Result<MapMergeResult> merge_maps(const msgs::FusionMap& a, const msgs::FusionMap& b, const MapMergeConfig& config = {});

}  // namespace hanzo::fusion::pipeline
