#include "hanzo/fusion/lidar/map_localization.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <unordered_set>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/lidar/surface_registration.hpp"

namespace hanzo::fusion::lidar {
namespace {

// Points thinned to one per `spacing` x `spacing` cell (the first one seen).
std::vector<Eigen::Vector2f> thin_2d(const std::vector<Eigen::Vector2f>& points, double spacing) {
  std::unordered_set<int64_t> taken;
  std::vector<Eigen::Vector2f> kept;
  for (const Eigen::Vector2f& point : points) {
    const int64_t x = static_cast<int64_t>(std::floor(point.x() / spacing));
    const int64_t y = static_cast<int64_t>(std::floor(point.y() / spacing));
    if (taken.insert((x << 32) ^ (y & 0xffffffff)).second) kept.push_back(point);
  }
  return kept;
}

// The likelihood grid of a 2D point set and its max-grids: level k holds, per cell, the maximum
// of level 0 over the 2^k x 2^k cells from it towards +x, +y (Hess et al. 2016, sec. V-B).
// The grid starts 2^depth cells below the points' box, so a block that begins outside the grid
// covers padding only and scores 0 like every cell outside.
class MaxGridStack {
 public:
  MaxGridStack(const std::vector<Eigen::Vector2f>& points, const Eigen::Vector2d& box_min, const Eigen::Vector2d& box_max,
               double resolution, double sigma, int depth)
      : resolution_(resolution) {
    const int pad = 1 << depth;
    const int blur = static_cast<int>(std::ceil(3.0 * sigma / resolution));
    origin_ = box_min - Eigen::Vector2d::Constant((pad + blur) * resolution);
    width_ = static_cast<int>(std::ceil((box_max.x() - origin_.x()) / resolution)) + blur + 1;
    height_ = static_cast<int>(std::ceil((box_max.y() - origin_.y()) / resolution)) + blur + 1;
    std::vector<float> likelihood(static_cast<std::size_t>(width_) * height_, 0.0f);
    const double inverse_two_sigma_squared = 1.0 / (2.0 * sigma * sigma);
    for (const Eigen::Vector2f& point : points) {
      const double gx = (point.x() - origin_.x()) / resolution, gy = (point.y() - origin_.y()) / resolution;
      const int cx = static_cast<int>(std::floor(gx)), cy = static_cast<int>(std::floor(gy));
      for (int y = std::max(0, cy - blur); y <= std::min(height_ - 1, cy + blur); ++y) {
        for (int x = std::max(0, cx - blur); x <= std::min(width_ - 1, cx + blur); ++x) {
          const double dx = (x + 0.5 - gx) * resolution, dy = (y + 0.5 - gy) * resolution;
          float& cell = likelihood[static_cast<std::size_t>(y) * width_ + x];
          cell = std::max(cell, static_cast<float>(std::exp(-(dx * dx + dy * dy) * inverse_two_sigma_squared)));
        }
      }
    }
    levels_.push_back(std::move(likelihood));
    for (int level = 1; level <= depth; ++level) {
      const int step = 1 << (level - 1);
      const std::vector<float>& below = levels_.back();
      std::vector<float> maxima(below.size());
      for (int y = 0; y < height_; ++y) {
        for (int x = 0; x < width_; ++x) {
          float value = below[static_cast<std::size_t>(y) * width_ + x];
          if (x + step < width_) value = std::max(value, below[static_cast<std::size_t>(y) * width_ + x + step]);
          if (y + step < height_) {
            value = std::max(value, below[static_cast<std::size_t>(y + step) * width_ + x]);
            if (x + step < width_) value = std::max(value, below[static_cast<std::size_t>(y + step) * width_ + x + step]);
          }
          maxima[static_cast<std::size_t>(y) * width_ + x] = value;
        }
      }
      levels_.push_back(std::move(maxima));
    }
  }

  /// Cell of a world position (may be outside the grid).
  Eigen::Vector2i cell(const Eigen::Vector2d& position) const {
    return ((position - origin_) / resolution_).array().floor().cast<int>();
  }
  Eigen::Vector2d center(const Eigen::Vector2i& cell) const { return origin_ + (cell.cast<double>().array() + 0.5).matrix() * resolution_; }

  /// Mean over `offsets` (cells relative to the sensor's cell) of level `level` at (x, y).
  float score(int level, int x, int y, const std::vector<Eigen::Vector2i>& offsets) const {
    const std::vector<float>& grid = levels_[static_cast<std::size_t>(level)];
    float sum = 0.0f;
    for (const Eigen::Vector2i& offset : offsets) {
      const int cx = x + offset.x(), cy = y + offset.y();
      if (cx < 0 || cy < 0 || cx >= width_ || cy >= height_) continue;
      sum += grid[static_cast<std::size_t>(cy) * width_ + cx];
    }
    return sum / static_cast<float>(offsets.size());
  }

 private:
  double resolution_;
  Eigen::Vector2d origin_;
  int width_ = 0, height_ = 0;
  std::vector<std::vector<float>> levels_;
};

struct SearchNode {
  int heading = 0;
  int x = 0, y = 0;  // sensor cell: the node covers x .. x + 2^level - 1 (same for y)
  float bound = 0.0f;
};

// Depth-first branch and bound (Hess et al. 2016, Algorithm 3), keeping the best `count`
// full-resolution poses that are distinct places and score at least rival_ratio x the best: a
// pose within `separation_cells` and `separation_headings` of a kept one replaces it only when
// it scores higher. Nodes are pruned against threshold(), so the kept poses are the exhaustive
// search's best distinct ones. Repetitive places (aisles of racks)
// give several; the caller verifies them in order.
class BranchAndBound {
 public:
  BranchAndBound(const MaxGridStack& grids, const std::vector<std::vector<Eigen::Vector2i>>& offsets, Eigen::Vector2i max_cell,
                 float min_score, float rival_ratio, std::size_t count, int separation_cells, int separation_headings, int headings)
      : grids_(grids),
        offsets_(offsets),
        max_cell_(std::move(max_cell)),
        min_score_(min_score),
        rival_ratio_(rival_ratio),
        count_(count),
        separation_cells_(separation_cells),
        separation_headings_(separation_headings),
        headings_(headings) {}

  void search(std::vector<SearchNode> nodes, int level) {
    std::sort(nodes.begin(), nodes.end(), [](const SearchNode& a, const SearchNode& b) { return a.bound > b.bound; });
    for (const SearchNode& node : nodes) {
      if (node.bound <= threshold()) break;  // sorted: no later node can beat the kept ones either
      if (level == 0) {
        keep(node);
        continue;
      }
      const int half = 1 << (level - 1);
      std::vector<SearchNode> children;
      for (int dy : {0, half}) {
        for (int dx : {0, half}) {
          const int x = node.x + dx, y = node.y + dy;
          if (x > max_cell_.x() || y > max_cell_.y()) continue;
          children.push_back({node.heading, x, y, grids_.score(level - 1, x, y, offsets_[static_cast<std::size_t>(node.heading)])});
          ++evaluated_;
        }
      }
      search(std::move(children), level - 1);
    }
  }
  std::size_t& evaluated() { return evaluated_; }
  /// Best first.
  std::vector<SearchNode> best() const {
    std::vector<SearchNode> sorted = kept_;
    std::sort(sorted.begin(), sorted.end(), [](const SearchNode& a, const SearchNode& b) { return a.bound > b.bound; });
    return sorted;
  }

 private:
  // Nodes at or below it cannot enter the kept set: below min_score, below rival_ratio x the
  // best kept score (not a rival in 2D), or below the lowest kept score once the set is full.
  float threshold() const {
    if (kept_.empty()) return min_score_;
    const auto [lowest, highest] = std::minmax_element(kept_.begin(), kept_.end(),
                                                       [](const SearchNode& a, const SearchNode& b) { return a.bound < b.bound; });
    float bound = std::max(min_score_, rival_ratio_ * highest->bound);
    if (kept_.size() >= count_) bound = std::max(bound, lowest->bound);
    return bound;
  }
  bool near(const SearchNode& a, const SearchNode& b) const {
    const int heading_gap = std::abs(a.heading - b.heading);
    return std::max(std::abs(a.x - b.x), std::abs(a.y - b.y)) <= separation_cells_ &&
           std::min(heading_gap, headings_ - heading_gap) <= separation_headings_;
  }
  void keep(const SearchNode& node) {
    for (SearchNode& kept : kept_) {
      if (!near(kept, node)) continue;
      if (node.bound > kept.bound) kept = node;
      return;
    }
    if (kept_.size() < count_) {
      kept_.push_back(node);
      return;
    }
    *std::min_element(kept_.begin(), kept_.end(), [](const SearchNode& a, const SearchNode& b) { return a.bound < b.bound; }) = node;
  }

  const MaxGridStack& grids_;
  const std::vector<std::vector<Eigen::Vector2i>>& offsets_;
  Eigen::Vector2i max_cell_;
  float min_score_;
  float rival_ratio_;
  std::size_t count_;
  int separation_cells_, separation_headings_, headings_;
  std::vector<SearchNode> kept_;
  std::size_t evaluated_ = 0;
};

// Free-space consistency of a localization: map points near the sensor that the sweep saw
// through (a return in their direction, farther than them by more than a margin) contradict
// the pose; points with a nearer return are occluded, points with no return tell nothing
// (rings are sparse). Directions are binned 1 deg in azimuth x 0.5 deg in elevation (a bin
// about one beam high, so the return and the map point are compared along nearly the same
// ray); a bin keeps its nearest return. The map points are those above the ground (the floor
// at grazing angles spans metres of range within a bin). Returns (consistent, seen through).
std::pair<std::size_t, std::size_t> free_space_check(const std::vector<Eigen::Vector3f>& sweep, const std::vector<Eigen::Vector3f>& map_points,
                                                     const SE3& T_map_sensor, double max_range) {
  constexpr int kAzimuthBins = 360, kElevationBins = 360;
  const auto bin_of = [](const Eigen::Vector3d& p) {
    const double azimuth = std::atan2(p.y(), p.x()), elevation = std::atan2(p.z(), p.head<2>().norm());
    const int a = std::clamp(static_cast<int>((azimuth + std::numbers::pi) / (2.0 * std::numbers::pi) * kAzimuthBins), 0, kAzimuthBins - 1);
    const int e = std::clamp(static_cast<int>((elevation + std::numbers::pi / 2) / std::numbers::pi * kElevationBins), 0, kElevationBins - 1);
    return e * kAzimuthBins + a;
  };
  std::vector<float> nearest(kAzimuthBins * kElevationBins, std::numeric_limits<float>::infinity());
  for (const Eigen::Vector3f& point : sweep) {
    if (!point.allFinite()) continue;
    float& range = nearest[static_cast<std::size_t>(bin_of(point.cast<double>()))];
    range = std::min(range, point.norm());
  }
  const SE3 T_sensor_map = T_map_sensor.inverse();
  std::size_t consistent = 0, seen_through = 0;
  for (const Eigen::Vector3f& map_point : map_points) {
    const Eigen::Vector3d p = T_sensor_map * map_point.cast<double>();
    const double range = p.norm();
    if (range < 1.0 || range > max_range) continue;
    const float measured = nearest[static_cast<std::size_t>(bin_of(p))];
    if (!std::isfinite(measured)) continue;
    const double margin = 0.5 + 0.05 * range;
    if (measured > range + margin) ++seen_through;
    else if (measured > range - margin) ++consistent;
  }
  return {consistent, seen_through};
}

double yaw_of(const SO3& rotation) {
  const Eigen::Matrix3d R = rotation.matrix();
  return std::atan2(R(1, 0), R(0, 0));
}

SO3 yaw_rotation(double yaw) { return SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), yaw); }

}  // namespace

Status MapLocalizerConfig::validate() const {
  if (!(grid_resolution > 0) || !(likelihood_sigma > 0)) return Error("grid_resolution, likelihood_sigma: must be > 0");
  if (!(slice_max_height > slice_min_height)) return Error("slice_max_height: must be > slice_min_height");
  if (!(ground_cell > 0) || !(query_max_range > 0) || !(query_point_spacing > 0)) {
    return Error("ground_cell, query_max_range, query_point_spacing: must be > 0");
  }
  if (branch_and_bound_depth < 0 || branch_and_bound_depth > 12) return Error("branch_and_bound_depth: must be in 0..12");
  if (max_grid_cells == 0 || candidates == 0 || search_cells == 0) return Error("max_grid_cells, candidates, search_cells: must be > 0");
  if (!(max_grid_resolution >= grid_resolution)) return Error("max_grid_resolution: must be >= grid_resolution");
  if (!(candidate_score_ratio > 0 && candidate_score_ratio <= 1)) return Error("candidate_score_ratio: must be in (0, 1]");
  if (!(min_score >= 0 && min_score <= 1)) return Error("min_score: must be in [0, 1]");
  if (!(max_seen_through_fraction >= 0 && max_seen_through_fraction <= 1)) return Error("max_seen_through_fraction: must be in [0, 1]");
  if (!(max_rmse > 0) || !(min_inlier_fraction >= 0 && min_inlier_fraction <= 1)) {
    return Error("max_rmse must be > 0, min_inlier_fraction in [0, 1]");
  }
  return ok_status();
}

Result<MapLocalizer> MapLocalizer::create(std::vector<Eigen::Vector3f> map_points, const MapLocalizerConfig& config,
                                          const LidarOdometryConfig& odometry) {
  HANZO_RETURN_IF_ERROR(with_context(config.validate(), "map localizer config"));
  std::erase_if(map_points, [](const Eigen::Vector3f& point) { return !point.allFinite(); });
  if (map_points.size() < config.min_slice_points) {
    return Error(fmt::format("map localization: the map has {} points (at least {} needed)", map_points.size(), config.min_slice_points));
  }
  MapLocalizer localizer(config, odometry);
  // Ground columns: the lowest point of each.
  Eigen::Vector2d lo = map_points.front().head<2>().cast<double>(), hi = lo;
  for (const Eigen::Vector3f& point : map_points) {
    lo = lo.cwiseMin(point.head<2>().cast<double>());
    hi = hi.cwiseMax(point.head<2>().cast<double>());
  }
  localizer.ground_origin_ = lo;
  localizer.ground_width_ = static_cast<int>((hi.x() - lo.x()) / config.ground_cell) + 1;
  localizer.ground_height_cells_ = static_cast<int>((hi.y() - lo.y()) / config.ground_cell) + 1;
  localizer.ground_.assign(static_cast<std::size_t>(localizer.ground_width_) * localizer.ground_height_cells_, std::nanf(""));
  for (const Eigen::Vector3f& point : map_points) {
    const int x = static_cast<int>((point.x() - lo.x()) / config.ground_cell);
    const int y = static_cast<int>((point.y() - lo.y()) / config.ground_cell);
    float& ground = localizer.ground_[static_cast<std::size_t>(y) * localizer.ground_width_ + x];
    if (std::isnan(ground) || point.z() < ground) ground = point.z();
  }
  // The slice between the heights above the local ground.
  for (const Eigen::Vector3f& point : map_points) {
    const double above = point.z() - *localizer.ground_height(point.x(), point.y());
    if (above >= config.slice_min_height && above <= config.slice_max_height) localizer.slice_.push_back(point.head<2>());
    if (above >= config.slice_min_height) localizer.structure_.push_back(point);
  }
  localizer.slice_ = thin_2d(localizer.slice_, config.grid_resolution / 2.0);
  if (localizer.slice_.size() < config.min_slice_points) {
    return Error(fmt::format("map localization: {} map points lie {}..{} m above the ground (at least {} needed)", localizer.slice_.size(),
                             config.slice_min_height, config.slice_max_height, config.min_slice_points));
  }
  localizer.min_corner_ = localizer.slice_.front().cast<double>();
  localizer.max_corner_ = localizer.min_corner_;
  for (const Eigen::Vector2f& point : localizer.slice_) {
    localizer.min_corner_ = localizer.min_corner_.cwiseMin(point.cast<double>());
    localizer.max_corner_ = localizer.max_corner_.cwiseMax(point.cast<double>());
  }
  // 3D targets, as LoopClosureDetector::verify builds them.
  const cloud::VoxelHashMapConfig& fine = odometry.map;
  localizer.coarse_.emplace(cloud::VoxelHashMapConfig{.voxel_size = 3.0 * fine.voxel_size, .max_points_per_voxel = 4 * fine.max_points_per_voxel,
                                                      .min_point_spacing = -1.0, .max_distance = 1e9});
  localizer.fine_.emplace(cloud::VoxelHashMapConfig{.voxel_size = fine.voxel_size, .max_points_per_voxel = fine.max_points_per_voxel,
                                                    .min_point_spacing = fine.min_point_spacing, .max_distance = 1e9});
  localizer.coarse_->add(map_points, {}, Eigen::Vector3d::Zero());
  localizer.fine_->add(map_points, {}, Eigen::Vector3d::Zero());
  localizer.points_ = std::move(map_points);
  return localizer;
}

std::optional<double> MapLocalizer::ground_height(double x, double y) const {
  const int cx = static_cast<int>(std::floor((x - ground_origin_.x()) / config_.ground_cell));
  const int cy = static_cast<int>(std::floor((y - ground_origin_.y()) / config_.ground_cell));
  // The nearest non-empty column within 3 columns (rings of growing size).
  for (int radius = 0; radius <= 3; ++radius) {
    float lowest = std::nanf("");
    for (int dy = -radius; dy <= radius; ++dy) {
      for (int dx = -radius; dx <= radius; ++dx) {
        if (std::max(std::abs(dx), std::abs(dy)) != radius) continue;
        const int gx = cx + dx, gy = cy + dy;
        if (gx < 0 || gy < 0 || gx >= ground_width_ || gy >= ground_height_cells_) continue;
        const float ground = ground_[static_cast<std::size_t>(gy) * ground_width_ + gx];
        if (!std::isnan(ground) && (std::isnan(lowest) || ground < lowest)) lowest = ground;
      }
    }
    if (!std::isnan(lowest)) return lowest;
  }
  return std::nullopt;
}

Result<MapLocalization> MapLocalizer::localize(const std::vector<Eigen::Vector3f>& points, const SO3& R_up_sensor,
                                               const MapLocalizationQuery& query) const {
  const auto started = std::chrono::steady_clock::now();
  if (!R_up_sensor.quaternion().coeffs().allFinite()) return Error("map localization: the sensor orientation is not finite");
  if (query.T_map_sensor_guess && !query.T_map_sensor_guess->matrix().allFinite()) return Error("map localization: the guess is not finite");
  if (query.T_map_sensor_guess && (!(query.linear_window >= 0) || !(query.angular_window >= 0))) {
    return Error("map localization: linear_window and angular_window must be >= 0");
  }
  // The sweep levelled: z up, the sensor's heading kept (R_level_sensor has no yaw).
  const SO3 R_level_sensor = yaw_rotation(-yaw_of(R_up_sensor)) * R_up_sensor;
  std::vector<Eigen::Vector3f> level;
  level.reserve(points.size());
  for (const Eigen::Vector3f& point : points) {
    if (point.allFinite()) level.push_back((R_level_sensor.matrix() * point.cast<double>()).cast<float>());
  }
  // The sensor's height above its ground: the 5th percentile of the returns 1-20 m around it.
  std::vector<float> near_heights;
  for (const Eigen::Vector3f& point : level) {
    const float range = point.head<2>().norm();
    if (range > 1.0f && range < 20.0f) near_heights.push_back(point.z());
  }
  if (near_heights.size() < config_.min_slice_points) {
    return Error(fmt::format("map localization: the sweep has {} returns 1-20 m around the sensor (at least {} needed)", near_heights.size(),
                             config_.min_slice_points));
  }
  const std::size_t fifth = near_heights.size() / 20;
  std::nth_element(near_heights.begin(), near_heights.begin() + static_cast<std::ptrdiff_t>(fifth), near_heights.end());
  const double sensor_height = -near_heights[fifth];
  std::vector<Eigen::Vector2f> slice;
  double farthest = 0.0;
  for (const Eigen::Vector3f& point : level) {
    const double above = point.z() + sensor_height;
    const double range = point.head<2>().norm();
    if (above < config_.slice_min_height || above > config_.slice_max_height || range > config_.query_max_range) continue;
    slice.push_back(point.head<2>());
    farthest = std::max(farthest, range);
  }
  slice = thin_2d(slice, config_.query_point_spacing);
  if (slice.size() > config_.max_query_points) {  // evenly: every k-th
    const std::size_t stride = (slice.size() + config_.max_query_points - 1) / config_.max_query_points;
    std::vector<Eigen::Vector2f> strided;
    for (std::size_t i = 0; i < slice.size(); i += stride) strided.push_back(slice[i]);
    slice = std::move(strided);
  }
  if (slice.size() < config_.min_slice_points) {
    return Error(fmt::format("map localization: {} sweep points lie {}..{} m above the ground (at least {} needed)", slice.size(),
                             config_.slice_min_height, config_.slice_max_height, config_.min_slice_points));
  }

  // The searched area: the map's slice, or the guess's window (its grid only as large as needed).
  Eigen::Vector2d area_min = min_corner_, area_max = max_corner_;
  double heading_center = 0.0, heading_window = std::numbers::pi;
  if (query.T_map_sensor_guess) {
    const Eigen::Vector2d guess = query.T_map_sensor_guess->translation().head<2>();
    area_min = guess - Eigen::Vector2d::Constant(query.linear_window);
    area_max = guess + Eigen::Vector2d::Constant(query.linear_window);
    heading_center = yaw_of(query.T_map_sensor_guess->rotation() * R_level_sensor.inverse());
    heading_window = std::min(query.angular_window, std::numbers::pi);
  }
  // Sensor positions searched (within the sweep's range of the map), and the map around them.
  const Eigen::Vector2d reach = Eigen::Vector2d::Constant(farthest);
  const Eigen::Vector2d grid_min = area_min.cwiseMax(min_corner_ - reach), grid_max = area_max.cwiseMin(max_corner_ + reach);
  const Eigen::Vector2d map_min = min_corner_.cwiseMax(grid_min - reach), map_max = max_corner_.cwiseMin(grid_max + reach);
  if ((grid_min.array() > grid_max.array()).any() || (map_min.array() > map_max.array()).any()) {
    return Error("map localization: the guess is farther from the map than the sweep reaches");
  }
  // Large searched areas at a coarser grid (the 3D refinement pulls a pose in from a metre off):
  // the cost grows with the cells searched x the headings.
  const double searched_area = (grid_max - grid_min).cwiseMax(Eigen::Vector2d::Constant(config_.grid_resolution)).prod();
  const double resolution =
      std::clamp(std::sqrt(searched_area / static_cast<double>(config_.search_cells)), config_.grid_resolution, config_.max_grid_resolution);
  const double sigma = config_.likelihood_sigma * resolution / config_.grid_resolution;
  const double cells = ((map_max - map_min) / resolution + Eigen::Vector2d::Constant((1 << config_.branch_and_bound_depth) + 10)).prod();
  if (!(cells <= static_cast<double>(config_.max_grid_cells))) {
    return Error(fmt::format("map localization: searching {:.0f} x {:.0f} m at {} m needs {:.1f} M cells (max_grid_cells {:.1f} M): "
                             "give a guess, or a coarser grid_resolution",
                             map_max.x() - map_min.x(), map_max.y() - map_min.y(), resolution, cells / 1e6, config_.max_grid_cells / 1e6));
  }
  std::vector<Eigen::Vector2f> target;
  for (const Eigen::Vector2f& point : slice_) {
    const Eigen::Vector2d p = point.cast<double>();
    if ((p.array() >= map_min.array()).all() && (p.array() <= map_max.array()).all()) target.push_back(point);
  }
  const int depth = config_.branch_and_bound_depth;
  const MaxGridStack grids(target, map_min, map_max, resolution, sigma, depth);

  // Headings: a step moves the farthest point by about one cell (Hess et al. eq. 7).
  const double step = std::acos(std::clamp(1.0 - resolution * resolution / (2.0 * farthest * farthest), -1.0, 1.0));
  const int half_steps = static_cast<int>(std::ceil(heading_window / step));
  const int headings = query.T_map_sensor_guess ? 2 * half_steps + 1 : static_cast<int>(std::ceil(2.0 * std::numbers::pi / step));
  const auto heading_of = [&](int index) {
    return query.T_map_sensor_guess ? heading_center + (index - half_steps) * step : index * step;
  };
  std::vector<std::vector<Eigen::Vector2i>> offsets(static_cast<std::size_t>(headings));
  for (int index = 0; index < headings; ++index) {
    const double c = std::cos(heading_of(index)), s = std::sin(heading_of(index));
    for (const Eigen::Vector2f& point : slice) {
      const double x = c * point.x() - s * point.y(), y = s * point.x() + c * point.y();
      offsets[static_cast<std::size_t>(index)].emplace_back(static_cast<int>(std::lround(x / resolution)),
                                                             static_cast<int>(std::lround(y / resolution)));
    }
  }
  const Eigen::Vector2i first_cell = grids.cell(grid_min), last_cell = grids.cell(grid_max);
  // Distinct places: 1 m or 10 deg apart.
  const int separation_cells = std::max(1, static_cast<int>(std::lround(1.0 / resolution)));
  const int separation_headings = std::max(1, static_cast<int>(std::lround(0.17 / step)));
  BranchAndBound search(grids, offsets, last_cell, static_cast<float>(config_.min_score), static_cast<float>(config_.candidate_score_ratio),
                        config_.candidates, separation_cells,
                        separation_headings, query.T_map_sensor_guess ? std::numeric_limits<int>::max() / 2 : headings);
  std::vector<SearchNode> top;
  const int top_step = 1 << depth;
  for (int index = 0; index < headings; ++index) {
    for (int y = first_cell.y(); y <= last_cell.y(); y += top_step) {
      for (int x = first_cell.x(); x <= last_cell.x(); x += top_step) {
        top.push_back({index, x, y, grids.score(depth, x, y, offsets[static_cast<std::size_t>(index)])});
      }
    }
  }
  search.evaluated() += top.size();
  search.search(std::move(top), depth);
  const std::vector<SearchNode> candidates = search.best();
  if (candidates.empty()) {
    return Error(fmt::format("map localization: no pose scores {} in 2D ({} headings, {} nodes searched)", config_.min_score, headings,
                             search.evaluated()));
  }

  // 3D, every candidate. The answer is the verified pose that fits best (lowest RMSE); another
  // distinct place (> 1 m away) that verifies with a comparable fit (RMSE <= 2 x the best's +
  // 2 cm) makes the sweep ambiguous (the same view from several places: repeated aisles), and
  // it is refused rather than guessed.
  cloud::PointCloud sweep;
  sweep.positions = points;
  std::erase_if(sweep.positions, [](const Eigen::Vector3f& point) { return !point.allFinite(); });
  const std::vector<Eigen::Vector3f> source = cloud::voxel_downsample(sweep, odometry_.source_voxel_size).positions;
  std::string first_failure;
  std::vector<MapLocalization> verified_poses;
  for (std::size_t rank = 0; rank < candidates.size(); ++rank) {
    const SearchNode& candidate = candidates[rank];
    const Eigen::Vector2d position = grids.center({candidate.x, candidate.y});
    const std::optional<double> ground = ground_height(position.x(), position.y());
    const double z = ground ? *ground + sensor_height
                            : (query.T_map_sensor_guess ? query.T_map_sensor_guess->translation().z() : sensor_height);
    const SE3 T_map_level(yaw_rotation(heading_of(candidate.heading)), Eigen::Vector3d(position.x(), position.y(), z));
    Result<MapLocalization> verified = verify(sweep.positions, source, T_map_level * SE3(R_level_sensor, Eigen::Vector3d::Zero()));
    if (!verified) {
      if (first_failure.empty()) {
        first_failure = fmt::format("the best (score {:.2f} at {:.1f}, {:.1f} m, {:.0f} deg): {}", candidate.bound, position.x(), position.y(),
                                    heading_of(candidate.heading) * 180.0 / std::numbers::pi, verified.error().message);
      }
      continue;
    }
    verified->score = candidate.bound;
    verified->candidate_rank = rank;
    verified_poses.push_back(std::move(verified).value());
  }
  if (verified_poses.empty()) {
    return Error(fmt::format("map localization: none of the {} best distinct 2D poses verified in 3D; {}", candidates.size(), first_failure));
  }
  const MapLocalization& best = *std::min_element(verified_poses.begin(), verified_poses.end(),
                                                  [](const MapLocalization& a, const MapLocalization& b) { return a.inlier_rmse < b.inlier_rmse; });
  std::vector<Eigen::Vector3d> rivals;  // distinct places fitting comparably, the best's included
  for (const MapLocalization& pose : verified_poses) {
    const Eigen::Vector3d place = pose.T_map_sensor.translation();
    if (pose.inlier_rmse > 2.0 * best.inlier_rmse + 0.02) continue;
    if (std::none_of(rivals.begin(), rivals.end(), [&](const Eigen::Vector3d& p) { return (p - place).norm() < 1.0; })) rivals.push_back(place);
  }
  if (rivals.size() > 1) {
    std::string where;
    for (const Eigen::Vector3d& place : rivals) where += fmt::format("{}({:.1f}, {:.1f})", where.empty() ? "" : ", ", place.x(), place.y());
    return Error(fmt::format("map localization: ambiguous: the sweep fits {} places of the map alike: {} m; give a guess", rivals.size(), where));
  }
  MapLocalization answer = best;
  answer.global = !query.T_map_sensor_guess;
  answer.nodes_evaluated = search.evaluated();
  answer.headings = static_cast<std::size_t>(headings);
  answer.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return answer;
}

Result<MapLocalization> MapLocalizer::verify(const std::vector<Eigen::Vector3f>& sweep, const std::vector<Eigen::Vector3f>& source,
                                             const SE3& guess) const {
  SurfaceRegistrationConfig registration = odometry_.registration;
  registration.prior_translation_sigma = 2.0;  // the 2D pose is a cell and a heading step off; its height more
  registration.prior_rotation_sigma = 0.2;
  registration.max_iterations = 40;
  SurfaceRegistrationConfig coarse_registration = registration;
  coarse_registration.max_neighbour_distance = 3.0 * odometry_.map.voxel_size;
  coarse_registration.initial_kernel_width = 2.0;
  coarse_registration.kernel_width = 0.3;
  coarse_registration.max_correspondence_distance = 1.0;
  SurfaceRegistrationResult pulled_in, refined;
  HANZO_ASSIGN_OR_RETURN(pulled_in, align_to_surfaces(source, *coarse_, guess, guess, coarse_registration));
  HANZO_ASSIGN_OR_RETURN(refined, align_to_surfaces(source, *fine_, pulled_in.T_map_source, pulled_in.T_map_source, registration));
  const double inliers = static_cast<double>(refined.correspondences) / static_cast<double>(source.size());
  if (!refined.converged || refined.inlier_rmse > config_.max_rmse || inliers < config_.min_inlier_fraction ||
      translation_constraint_ratio(refined.information) < odometry_.degeneracy_ratio) {
    return Error(fmt::format("registration: converged {}, inlier RMSE {:.3f} m (max {}), {:.0f} % matched (min {:.0f} %)", refined.converged,
                             refined.inlier_rmse, config_.max_rmse, 100.0 * inliers, 100.0 * config_.min_inlier_fraction));
  }
  const auto [consistent, seen_through] = free_space_check(sweep, structure_, refined.T_map_source, config_.query_max_range);
  const double seen_through_fraction =
      consistent + seen_through > 0 ? static_cast<double>(seen_through) / static_cast<double>(consistent + seen_through) : 1.0;
  if (seen_through_fraction > config_.max_seen_through_fraction) {
    return Error(fmt::format("free space: the sweep saw through {:.0f} % of the map points in its view (max {:.0f} %)",
                             100.0 * seen_through_fraction, 100.0 * config_.max_seen_through_fraction));
  }
  MapLocalization result;
  result.T_map_sensor = refined.T_map_source;
  result.inlier_rmse = refined.inlier_rmse;
  result.inlier_fraction = inliers;
  result.seen_through_fraction = seen_through_fraction;
  return result;
}

}  // namespace hanzo::fusion::lidar
