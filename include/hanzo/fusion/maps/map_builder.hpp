#pragma once
// Mapping with known poses: scans (LiDAR sweeps or planar laser scans, in their sensor frame)
// and the sensor's world pose at each scan go in; the layers of a FusionMap come out. It is
// what `hanzo-fusion map build` runs on a log and a trajectory, and what a SLAM pipeline feeds
// with its keyframes.
//
// Layers (each optional):
//  - 2D occupancy: returns whose height relative to the sensor is inside the height band are
//    projected onto the world XY plane and ray cast from the sensor's XY position (a planar
//    laser's returns all qualify; for a 3D LiDAR the band keeps obstacles and drops ground and
//    ceiling).
//  - 3D occupancy: every return ray cast in 3D.
//  - Point map: every scan a keyframe (see point_map.hpp).
//  - TSDF: every return integrated along its ray (see tsdf.hpp); write_layers() adds its
//    marching-cubes mesh.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/maps/occupancy_grid.hpp"
#include "hanzo/fusion/maps/geometric_labels.hpp"
#include "hanzo/fusion/maps/point_map.hpp"
#include "hanzo/fusion/maps/tsdf.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct MapBuilderConfig {
  bool occupancy_2d = true;
  OccupancyConfig occupancy_2d_config;
  /// Returns with min_height <= z_world - z_sensor <= max_height (m) enter the 2D grid.
  double min_height = -0.3;
  double max_height = 1.0;
  bool occupancy_3d = false;
  OccupancyConfig occupancy_3d_config{.resolution = 0.2};
  bool points = true;
  PointMapConfig point_map;
  bool tsdf = false;
  TsdfConfig tsdf_config;
  /// The point layer and the 2D grid of write_map() carry geometric labels (floor, wall,
  /// obstacle, traversable: geometric_labels.hpp).
  bool geometric_labels = true;
  GeometricLabelConfig labels;

  Status validate() const;
};

/// What a scan is inserted for. A SLAM pipeline keeps every sweep in the grids (free space
/// needs many rays through a cell; `map build` inserts every scan) but only keyframes in the
/// point map.
enum class ScanUse {
  kAllLayers,  ///< every layer; the point map keeps the scan as its next keyframe
  kGridsOnly,  ///< occupancy and TSDF only
};

struct MapBuilderSummary {
  uint64_t scans = 0;            ///< every scan inserted
  uint64_t point_keyframes = 0;  ///< scans the point map kept (ScanUse::kAllLayers)
  uint64_t points = 0;        ///< returns integrated (before downsampling)
  uint64_t points_in_2d_band = 0;
};

class MapBuilder {
 public:
  static Result<MapBuilder> create(const MapBuilderConfig& config);

  /// Integrates one scan. Invalid clouds or poses are rejected, changing nothing.
  /// point_classes (optional): a segmentation class per scan point (class_index() values or
  /// msgs::kNoClass) for the point map (PointMap::add_keyframe).
  Status insert(const SE3& T_world_sensor, const cloud::PointCloud& scan_in_sensor_frame, ScanUse use = ScanUse::kAllLayers,
                std::span<const uint16_t> point_classes = {});
  /// A later scan's segmentation classes (one per point, class_index() values or
  /// msgs::kNoClass) for the newest point-map keyframe's points (PointMap::add_class_votes);
  /// nothing without a point map or a keyframe.
  Status add_class_votes(const SE3& T_world_sensor, const std::vector<Eigen::Vector3f>& points_in_sensor_frame,
                         std::span<const uint16_t> point_classes);
  /// Moves earlier point-map keyframes (numbered 0, 1, ... in the order of the kAllLayers
  /// inserts) after a correction. Occupancy layers keep what was integrated (rebuild them from the corrected
  /// poses when the correction is large).
  Status correct_poses(const std::map<uint64_t, SE3>& T_world_sensor_by_scan);

  /// Fills the map's layers (points; occupancy: the 3D grid when built, else the 2D one; TSDF
  /// and its mesh) and leaves its metadata as given.
  void write_layers(msgs::FusionMap& map) const;
  /// write_layers, with the point layer's geometric labels when geometric_labels is set and
  /// the grid cells' segmentation classes when the points have them (cell_classes.hpp): the
  /// map a session or `map build` hands out; incremental map updates use write_layers.
  void write_map(msgs::FusionMap& map) const;
  /// The point map's label table index of a segmentation class (PointMap::class_index);
  /// msgs::kNoClass without a point map.
  uint16_t class_index(std::string_view name);

  const std::optional<OccupancyGrid2D>& occupancy_2d() const { return occupancy_2d_; }
  const std::optional<OccupancyGrid3D>& occupancy_3d() const { return occupancy_3d_; }
  const std::optional<PointMap>& point_map() const { return point_map_; }
  const std::optional<TsdfVolume>& tsdf() const { return tsdf_; }
  const MapBuilderSummary& summary() const { return summary_; }
  std::size_t memory_bytes() const;

 private:
  explicit MapBuilder(const MapBuilderConfig& config) : config_(config) {}

  MapBuilderConfig config_;
  std::optional<OccupancyGrid2D> occupancy_2d_;
  std::optional<OccupancyGrid3D> occupancy_3d_;
  std::optional<PointMap> point_map_;
  std::optional<TsdfVolume> tsdf_;
  MapBuilderSummary summary_;
};

}  // namespace hanzo::fusion::maps
