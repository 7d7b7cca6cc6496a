#include "hanzo/fusion/maps/geometric_labels.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/local_geometry.hpp"
#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::maps {
namespace {

double degrees_to_radians(double degrees) { return degrees * M_PI / 180.0; }

bool horizontal_surface(const Eigen::Vector3f& normal, const GeometricLabelConfig& config) {
  return std::abs(normal.z()) >= std::cos(degrees_to_radians(config.horizontal_max_tilt_deg));
}

bool vertical_surface(const Eigen::Vector3f& normal, const GeometricLabelConfig& config) {
  return std::abs(normal.z()) <= std::sin(degrees_to_radians(config.vertical_max_tilt_deg));
}

// Step 2 of the header: the lowest well-filled bin of the horizontal points' heights.
std::optional<double> floor_height(const std::vector<Eigen::Vector3f>& points, const std::vector<Eigen::Vector3f>& normals,
                                   const GeometricLabelConfig& config) {
  std::map<long, std::size_t> bins;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (horizontal_surface(normals[i], config)) ++bins[std::lround(std::floor(points[i].z() / config.histogram_bin_m))];
  }
  if (bins.empty()) return std::nullopt;
  std::size_t fullest = 0;
  for (const auto& [bin, count] : bins) fullest = std::max(fullest, count);
  for (const auto& [bin, count] : bins) {
    if (static_cast<double>(count) >= config.floor_min_share * static_cast<double>(fullest)) return (static_cast<double>(bin) + 0.5) * config.histogram_bin_m;
  }
  return std::nullopt;
}

}  // namespace

void label_grid(msgs::OccupancyGridLayer& grid, const msgs::PointLayer& points, const std::vector<Eigen::Vector3f>& normals,
                double occupied_threshold, double free_threshold, const TraversabilityConfig& traversability) {
  grid.labels.clear();
  if (grid.size_z != 1 || grid.occupancy.size() != static_cast<std::size_t>(grid.size_x) * grid.size_y) return;
  // Wall and obstacle points per cell column.
  std::vector<std::array<uint32_t, 2>> column_votes(grid.occupancy.size(), {0, 0});
  if (points.labels.size() == points.points.size()) {
    const SE3 T_grid_world = grid.origin.to_se3().inverse();
    for (std::size_t i = 0; i < points.points.size(); ++i) {
      const bool wall = points.labels[i] == msgs::SemanticLabel::kWall;
      if (!wall && points.labels[i] != msgs::SemanticLabel::kObstacle) continue;
      const Eigen::Vector3d in_grid = T_grid_world * points.points[i].cast<double>();
      const auto x = static_cast<long>(std::floor(in_grid.x() / grid.resolution));
      const auto y = static_cast<long>(std::floor(in_grid.y() / grid.resolution));
      if (x < 0 || y < 0 || x >= static_cast<long>(grid.size_x) || y >= static_cast<long>(grid.size_y)) continue;
      ++column_votes[static_cast<std::size_t>(y) * grid.size_x + static_cast<std::size_t>(x)][wall ? 0 : 1];
    }
  }
  const std::vector<GroundCell> ground = ground_cells(grid, points.points, normals, traversability);
  grid.labels.resize(grid.occupancy.size(), msgs::SemanticLabel::kUnknown);
  for (std::size_t cell = 0; cell < grid.occupancy.size(); ++cell) {
    const float probability = grid.occupancy[cell];
    if (probability >= occupied_threshold) {
      const auto& [walls, obstacles] = column_votes[cell];
      grid.labels[cell] = walls > 0 && walls >= obstacles ? msgs::SemanticLabel::kWall : msgs::SemanticLabel::kObstacle;
    } else if (!ground.empty() && ground[cell].has_ground()) {
      grid.labels[cell] = ground[cell].traversable(traversability) ? msgs::SemanticLabel::kTraversable : msgs::SemanticLabel::kObstacle;
    } else if (probability <= free_threshold) {
      grid.labels[cell] = msgs::SemanticLabel::kTraversable;
    }
  }
}

const char* semantic_label_name(msgs::SemanticLabel label) {
  switch (label) {
    case msgs::SemanticLabel::kFloor: return "floor";
    case msgs::SemanticLabel::kWall: return "wall";
    case msgs::SemanticLabel::kObstacle: return "obstacle";
    case msgs::SemanticLabel::kTraversable: return "traversable";
    case msgs::SemanticLabel::kUnknown: break;
  }
  return "unknown";
}

Status GeometricLabelConfig::validate() const {
  if (normal_neighbours < 3) return Error(fmt::format("normal_neighbours: {} (at least 3)", normal_neighbours));
  if (!(horizontal_max_tilt_deg > 0.0 && horizontal_max_tilt_deg < 90.0)) return Error(fmt::format("horizontal_max_tilt_deg: {} (0 to 90)", horizontal_max_tilt_deg));
  if (!(vertical_max_tilt_deg > 0.0 && vertical_max_tilt_deg < 90.0)) return Error(fmt::format("vertical_max_tilt_deg: {} (0 to 90)", vertical_max_tilt_deg));
  if (!(floor_tolerance_m > 0.0)) return Error(fmt::format("floor_tolerance_m: {} (> 0)", floor_tolerance_m));
  if (!(robot_height_m > floor_tolerance_m)) return Error(fmt::format("robot_height_m: {} (above floor_tolerance_m)", robot_height_m));
  if (!(histogram_bin_m > 0.0)) return Error(fmt::format("histogram_bin_m: {} (> 0)", histogram_bin_m));
  if (!(floor_min_share > 0.0 && floor_min_share <= 1.0)) return Error(fmt::format("floor_min_share: {} (0 to 1)", floor_min_share));
  if (Status valid = traversability.validate(); !valid) return Error("traversability." + valid.error().message);
  return ok_status();
}

msgs::SemanticLabel geometric_label(const Eigen::Vector3f& normal, double z, std::optional<double> floor, const GeometricLabelConfig& config) {
  const std::optional<double> height = floor ? std::optional<double>(z - *floor) : std::nullopt;
  if (height && horizontal_surface(normal, config) && std::abs(*height) <= config.floor_tolerance_m) return msgs::SemanticLabel::kFloor;
  if (vertical_surface(normal, config)) return msgs::SemanticLabel::kWall;
  if (height && *height > config.floor_tolerance_m && *height <= config.robot_height_m) return msgs::SemanticLabel::kObstacle;
  return msgs::SemanticLabel::kUnknown;
}

Result<GeometricLabelSummary> label_points(msgs::PointLayer& layer, const GeometricLabelConfig& config, std::vector<Eigen::Vector3f>* normals) {
  HANZO_RETURN_IF_ERROR(config.validate());
  GeometricLabelSummary summary;
  layer.labels.assign(layer.points.size(), msgs::SemanticLabel::kUnknown);
  if (layer.points.size() < 3) {
    summary.counts[static_cast<std::size_t>(msgs::SemanticLabel::kUnknown)] = layer.points.size();
    return summary;
  }
  cloud::PointCloud cloud;
  cloud.positions = layer.points;
  cloud::LocalGeometryConfig geometry;
  geometry.num_neighbors = config.normal_neighbours;
  cloud::estimate_local_geometry(cloud, geometry);
  summary.floor_height = floor_height(cloud.positions, cloud.normals, config);
  for (std::size_t i = 0; i < layer.points.size(); ++i) {
    layer.labels[i] = geometric_label(cloud.normals[i], layer.points[i].z(), summary.floor_height, config);
    ++summary.counts[static_cast<std::size_t>(layer.labels[i])];
  }
  if (normals != nullptr) *normals = std::move(cloud.normals);
  return summary;
}

}  // namespace hanzo::fusion::maps
