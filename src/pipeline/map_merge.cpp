#include "hanzo/fusion/pipeline/map_merge.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <unordered_map>
#include <unordered_set>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::pipeline {
namespace {

struct View {
  Eigen::Vector3d sensor = Eigen::Vector3d::Zero();  // B's frame
  std::vector<Eigen::Vector3f> points;               // sensor frame (B's axes)
};

struct Localized {
  SE3 T_a_b;
  double rmse = 0.0;
};

// One key per voxel (21 bits per axis, offset so that +-1M voxels fit).
uint64_t voxel_key(const Eigen::Vector3f& point, double voxel) {
  const auto axis = [voxel](float value) { return static_cast<uint64_t>(static_cast<int64_t>(std::floor(value / voxel)) + (1 << 20)) & 0x1FFFFFU; };
  return (axis(point.x()) << 42U) | (axis(point.y()) << 21U) | axis(point.z());
}

// B's views: centres of the query_spacing cells with the most points, the sensor above the
// cell's lowest point; each view's points as a z-buffer from the sensor.
std::vector<View> views_of(const std::vector<Eigen::Vector3f>& points, const MapMergeConfig& config) {
  struct Cell {
    std::size_t count = 0;
    float lowest = std::numeric_limits<float>::infinity();
  };
  std::map<std::pair<int64_t, int64_t>, Cell> cells;
  for (const Eigen::Vector3f& point : points) {
    Cell& cell = cells[{static_cast<int64_t>(std::floor(point.x() / config.query_spacing)), static_cast<int64_t>(std::floor(point.y() / config.query_spacing))}];
    ++cell.count;
    cell.lowest = std::min(cell.lowest, point.z());
  }
  std::vector<std::pair<std::pair<int64_t, int64_t>, Cell>> ranked(cells.begin(), cells.end());
  std::sort(ranked.begin(), ranked.end(), [](const auto& a, const auto& b) { return a.second.count > b.second.count; });
  if (ranked.size() > config.max_views) ranked.resize(config.max_views);
  std::vector<View> views;
  const double bins_per_turn = 2.0 * std::numbers::pi / config.view_resolution;
  for (const auto& [index, cell] : ranked) {
    View view;
    view.sensor = Eigen::Vector3d((static_cast<double>(index.first) + 0.5) * config.query_spacing, (static_cast<double>(index.second) + 0.5) * config.query_spacing,
                                  cell.lowest + config.sensor_height);
    std::unordered_map<uint64_t, Eigen::Vector3f> nearest;  // per azimuth x elevation cell
    for (const Eigen::Vector3f& point : points) {
      const Eigen::Vector3d offset = point.cast<double>() - view.sensor;
      const double horizontal = offset.head<2>().norm();
      if (horizontal > config.query_radius || horizontal < 0.5) continue;
      const auto azimuth = static_cast<uint64_t>((std::atan2(offset.y(), offset.x()) + std::numbers::pi) / config.view_resolution);
      const auto elevation = static_cast<uint64_t>((std::atan2(offset.z(), horizontal) + std::numbers::pi) / config.view_resolution);
      const uint64_t key = elevation * static_cast<uint64_t>(bins_per_turn + 1.0) + azimuth;
      const auto [entry, inserted] = nearest.try_emplace(key, offset.cast<float>());
      if (!inserted && offset.squaredNorm() < entry->second.cast<double>().squaredNorm()) entry->second = offset.cast<float>();
    }
    view.points.reserve(nearest.size());
    for (const auto& [key, point] : nearest) view.points.push_back(point);
    views.push_back(std::move(view));
  }
  return views;
}

bool agree(const SE3& a, const SE3& b, const MapMergeConfig& config) {
  const SE3 difference = a.inverse() * b;
  return difference.translation().norm() <= config.agreement_translation && difference.rotation().angle() <= config.agreement_rotation;
}

// A's points with B's moved ones in voxels A has no point in; attributes both maps carry.
msgs::PointLayer join_points(const msgs::PointLayer& a, const msgs::PointLayer& b, const SE3& T_a_b, std::size_t& added) {
  msgs::PointLayer joined = a;
  const double voxel = a.voxel_size > 0.0 ? a.voxel_size : 0.1;
  std::unordered_set<uint64_t> taken;
  taken.reserve(a.points.size() + b.points.size());
  for (const Eigen::Vector3f& point : a.points) taken.insert(voxel_key(point, voxel));
  const bool std_both = !a.position_std.empty() && !b.position_std.empty();
  const bool labels_both = !a.labels.empty() && !b.labels.empty();
  const bool intensities_both = !a.intensities.empty() && !b.intensities.empty();
  if (!std_both) joined.position_std.clear();
  if (!labels_both) joined.labels.clear();
  if (!intensities_both) joined.intensities.clear();
  joined.classes.clear();  // class indices refer to each map's own table
  joined.class_probability.clear();
  added = 0;
  for (std::size_t i = 0; i < b.points.size(); ++i) {
    const Eigen::Vector3f moved = (T_a_b * b.points[i].cast<double>()).cast<float>();
    if (!taken.insert(voxel_key(moved, voxel)).second) continue;
    joined.points.push_back(moved);
    if (std_both) joined.position_std.push_back(b.position_std[i]);
    if (labels_both) joined.labels.push_back(b.labels[i]);
    if (intensities_both) joined.intensities.push_back(b.intensities[i]);
    ++added;
  }
  return joined;
}


}  // namespace

std::vector<std::string> layers_besides_points(const msgs::FusionMap& map) {
  std::vector<std::string> names;
  if (map.occupancy) names.emplace_back("occupancy");
  if (map.tsdf) names.emplace_back("tsdf");
  if (map.mesh) names.emplace_back("mesh");
  if (map.visual_landmarks) names.emplace_back("visual_landmarks");
  if (map.gaussian_splats) names.emplace_back("gaussian_splats");
  if (map.neural_field) names.emplace_back("neural_field");
  if (map.lidar_keyframes) names.emplace_back("lidar_keyframes");
  return names;
}

Result<MapMergeResult> merge_maps(const msgs::FusionMap& a, const msgs::FusionMap& b, const MapMergeConfig& config) {
  if (!a.points || a.points->points.empty()) return Error(fmt::format("map A ({}): no points to localize in", a.map_id));
  if (!b.points || b.points->points.empty()) return Error(fmt::format("map B ({}): no points to localize", b.map_id));
  Result<lidar::MapLocalizer> created = lidar::MapLocalizer::create(a.points->points, config.localizer, config.odometry);
  if (!created) return Error(fmt::format("map A ({}): {}", a.map_id, created.error().message));
  const lidar::MapLocalizer& localizer = *created;
  MapMergeResult result;
  std::vector<Localized> localized;
  std::string first_refusal;
  for (const View& view : views_of(b.points->points, config)) {
    ++result.views;
    Result<lidar::MapLocalization> found = localizer.localize(view.points, SO3());
    if (!found) {
      if (first_refusal.empty()) first_refusal = found.error().message;
      continue;
    }
    localized.push_back({found->T_map_sensor * SE3(SO3(), view.sensor).inverse(), found->inlier_rmse});
  }
  result.localized = localized.size();
  std::size_t best = 0, best_count = 0;
  for (std::size_t i = 0; i < localized.size(); ++i) {
    const std::size_t count =
        static_cast<std::size_t>(std::count_if(localized.begin(), localized.end(), [&](const Localized& other) { return agree(localized[i].T_a_b, other.T_a_b, config); }));
    if (count > best_count || (count == best_count && localized[i].rmse < localized[best].rmse)) {
      best = i;
      best_count = count;
    }
  }
  if (localized.empty()) {
    return Error(fmt::format("no view of B ({}) localized in A ({}): {} views tried; the first refusal: {}", b.map_id, a.map_id, result.views, first_refusal));
  }
  const auto needed = std::max(config.min_agreeing, static_cast<std::size_t>(std::ceil(config.min_agreeing_share * static_cast<double>(localized.size()))));
  if (best_count < needed) {
    return Error(fmt::format("B's views localized in A disagree: {} of {} views localized, at most {} agree (needed {}): the maps share no place "
                             "for certain",
                             localized.size(), result.views, best_count, needed));
  }
  // The best-fitting view among those that agree with the most.
  const SE3 reference = localized[best].T_a_b;
  for (std::size_t i = 0; i < localized.size(); ++i) {
    if (agree(localized[i].T_a_b, reference, config) && localized[i].rmse < localized[best].rmse) best = i;
  }
  result.T_a_b = localized[best].T_a_b;
  result.agreeing = best_count;
  result.merged = a;
  result.merged.points = join_points(*a.points, *b.points, result.T_a_b, result.points_from_b);
  result.merged.provenance.input_logs.insert(result.merged.provenance.input_logs.end(), b.provenance.input_logs.begin(), b.provenance.input_logs.end());
  result.dropped_layers = layers_besides_points(b);
  // The joined points hold B's too: a keyframe graph rebuilt from A's keyframes alone would
  // lose them.
  if (result.merged.lidar_keyframes) {
    result.merged.lidar_keyframes.reset();
    if (!b.lidar_keyframes) result.dropped_layers.emplace_back("lidar_keyframes (A's)");
  }
  logger()->info("map merge: B ({}) in A ({}): {} of {} views localized, {} agree; {} points added", b.map_id, a.map_id, result.localized, result.views,
                 result.agreeing, result.points_from_b);
  return result;
}

}  // namespace hanzo::fusion::pipeline
