#include "hanzo/fusion/maps/map_builder.hpp"

#include <cmath>
#include <limits>
#include <vector>

#include <fmt/format.h>

#include "hanzo/fusion/maps/cell_classes.hpp"

namespace hanzo::fusion::maps {

Status MapBuilderConfig::validate() const {
  if (!occupancy_2d && !occupancy_3d && !points && !tsdf) return Error{"map builder: no layer selected", "layers"};
  if (occupancy_2d) {
    HANZO_RETURN_IF_ERROR(occupancy_2d_config.validate());
    if (!(std::isfinite(min_height) && std::isfinite(max_height) && min_height <= max_height)) {
      return Error{fmt::format("map builder: height band [{}, {}] m is not an interval", min_height, max_height), "min_height"};
    }
  }
  if (occupancy_3d) HANZO_RETURN_IF_ERROR(occupancy_3d_config.validate());
  if (points) HANZO_RETURN_IF_ERROR(point_map.validate());
  if (tsdf) HANZO_RETURN_IF_ERROR(tsdf_config.validate());
  if (geometric_labels) HANZO_RETURN_IF_ERROR(labels.validate());
  return ok_status();
}

Result<MapBuilder> MapBuilder::create(const MapBuilderConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  MapBuilder builder(config);
  if (config.occupancy_2d) builder.occupancy_2d_.emplace(config.occupancy_2d_config);
  if (config.occupancy_3d) builder.occupancy_3d_.emplace(config.occupancy_3d_config);
  if (config.points) builder.point_map_.emplace(config.point_map);
  if (config.tsdf) builder.tsdf_.emplace(config.tsdf_config);
  return builder;
}

Status MapBuilder::insert(const SE3& T_world_sensor, const cloud::PointCloud& scan_in_sensor_frame, ScanUse use,
                          std::span<const uint16_t> point_classes) {
  if (!T_world_sensor.matrix().allFinite()) return Error{"map builder: sensor pose is not finite", "T_world_sensor"};
  HANZO_RETURN_IF_ERROR(scan_in_sensor_frame.validate());
  const Eigen::Matrix3d rotation = T_world_sensor.rotation().matrix();
  const Eigen::Vector3d origin = T_world_sensor.translation();
  std::vector<Eigen::Vector3d> world(scan_in_sensor_frame.size());
  for (std::size_t i = 0; i < world.size(); ++i) world[i] = rotation * scan_in_sensor_frame.positions[i].cast<double>() + origin;

  // Check every layer's preconditions before changing any (the grids reject points outside
  // their index range; a scan must go into all layers or none).
  std::vector<Eigen::Vector2d> planar;
  if (occupancy_2d_) {
    planar.reserve(world.size());
    for (const Eigen::Vector3d& point : world) {
      const double height = point.z() - origin.z();
      if (height >= config_.min_height && height <= config_.max_height) planar.push_back(point.head<2>());
    }
  }
  double finest = std::numeric_limits<double>::infinity();
  if (occupancy_2d_) finest = config_.occupancy_2d_config.resolution;
  if (occupancy_3d_) finest = std::min(finest, config_.occupancy_3d_config.resolution);
  const double limit = std::min(1e7, (double{1 << 22} - 1) * finest);
  for (const Eigen::Vector3d& point : world) {
    if (!(point.array().abs() < limit).all()) {
      return Error{fmt::format("map builder: a return lies {} m from the world origin, past the map's range", point.norm()),
                   "points"};
    }
  }
  if (!(origin.array().abs() < limit).all()) return Error{"map builder: sensor position is past the map's range", "T_world_sensor"};

  if (occupancy_2d_) HANZO_RETURN_IF_ERROR(occupancy_2d_->insert_scan(origin.head<2>(), planar));
  if (occupancy_3d_) HANZO_RETURN_IF_ERROR(occupancy_3d_->insert_scan(origin, world));
  if (point_map_ && use == ScanUse::kAllLayers) {
    HANZO_RETURN_IF_ERROR(point_map_->add_keyframe(summary_.point_keyframes, T_world_sensor, scan_in_sensor_frame, point_classes));
    ++summary_.point_keyframes;
  }
  if (tsdf_) HANZO_RETURN_IF_ERROR(tsdf_->integrate_scan(origin, world));
  ++summary_.scans;
  summary_.points += world.size();
  summary_.points_in_2d_band += planar.size();
  return ok_status();
}

Status MapBuilder::add_class_votes(const SE3& T_world_sensor, const std::vector<Eigen::Vector3f>& points_in_sensor_frame,
                                   std::span<const uint16_t> point_classes) {
  if (!point_map_ || summary_.point_keyframes == 0) return ok_status();
  return point_map_->add_class_votes(summary_.point_keyframes - 1, T_world_sensor, points_in_sensor_frame, point_classes);
}

Status MapBuilder::correct_poses(const std::map<uint64_t, SE3>& T_world_sensor_by_scan) {
  if (!point_map_) return ok_status();
  return point_map_->set_poses(T_world_sensor_by_scan);
}

void MapBuilder::write_layers(msgs::FusionMap& map) const {
  if (point_map_) {
    map.points = point_map_->to_layer();
    map.semantic_classes = point_map_->semantic_classes();
  }
  if (tsdf_) {
    map.tsdf = tsdf_->to_layer();
    map.mesh = tsdf_->extract_mesh();
  }
  if (occupancy_3d_) {
    map.occupancy = occupancy_3d_->to_layer();
  } else if (occupancy_2d_) {
    map.occupancy = occupancy_2d_->to_layer();
  }
}

void MapBuilder::write_map(msgs::FusionMap& map) const {
  write_layers(map);
  if (map.points && !map.points->classes.empty() && map.occupancy) classify_cells(*map.occupancy, *map.points);
  if (!config_.geometric_labels || !map.points) return;
  // The configuration was validated at creation: labelling cannot fail.
  std::vector<Eigen::Vector3f> normals;
  (void)label_points(*map.points, config_.labels, &normals);
  if (map.occupancy && occupancy_3d_) {
    label_voxels(*map.occupancy, *map.points, config_.occupancy_3d_config.occupied_threshold);
  } else if (map.occupancy) {
    label_grid(*map.occupancy, *map.points, normals, config_.occupancy_2d_config.occupied_threshold, config_.occupancy_2d_config.free_threshold,
               config_.labels.traversability);
  }
  if (map.mesh) label_mesh(*map.mesh, *map.points, 2.0 * config_.tsdf_config.voxel_size);
}

uint16_t MapBuilder::class_index(std::string_view name) { return point_map_ ? point_map_->class_index(name) : msgs::kNoClass; }

std::size_t MapBuilder::memory_bytes() const {
  return (occupancy_2d_ ? occupancy_2d_->memory_bytes() : 0) + (occupancy_3d_ ? occupancy_3d_->memory_bytes() : 0) +
         (point_map_ ? point_map_->memory_bytes() : 0) + (tsdf_ ? tsdf_->memory_bytes() : 0);
}

}  // namespace hanzo::fusion::maps
