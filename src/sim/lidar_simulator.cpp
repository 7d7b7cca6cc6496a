#include "hanzo/fusion/sim/lidar_simulator.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "hanzo/fusion/core/thread_sanitizer.hpp"
#include "hanzo/fusion/core/enum_names.hpp"

namespace hanzo::fusion::sim {
namespace {

constexpr EnumNames<LidarModel, 4> kLidarModelNames{{{LidarModel::kVelodyneVlp16, "velodyne_vlp16"},
                                                     {LidarModel::kVelodyneHdl64, "velodyne_hdl64"},
                                                     {LidarModel::kOusterOs1_64, "ouster_os1_64"},
                                                     {LidarModel::kPlanarLaser, "planar_laser"}}};

constexpr double kDegree = std::numbers::pi / 180.0;
constexpr float kPhantomIntensity = 0.02F;

}  // namespace

std::string_view to_string(LidarModel model) { return enum_name(kLidarModelNames, model); }
std::optional<LidarModel> lidar_model_from_string(std::string_view name) { return enum_from_name(kLidarModelNames, name); }

LidarPattern LidarPattern::preset(LidarModel model) {
  LidarPattern pattern;
  switch (model) {
    case LidarModel::kVelodyneVlp16:
      for (int ring = 0; ring < 16; ++ring) pattern.elevations.push_back((-15.0 + 2.0 * ring) * kDegree);
      pattern.columns = 1800;
      pattern.min_range = 0.5;
      pattern.max_range = 100.0;
      break;
    case LidarModel::kVelodyneHdl64:
      for (int i = 31; i >= 0; --i) pattern.elevations.push_back((-8.83 - 0.5 * i) * kDegree);      // lower block
      for (int i = 31; i >= 0; --i) pattern.elevations.push_back((2.0 - i / 3.0) * kDegree);        // upper block
      pattern.columns = 2083;
      pattern.min_range = 0.9;
      pattern.max_range = 120.0;
      break;
    case LidarModel::kOusterOs1_64:
      for (int ring = 0; ring < 64; ++ring) pattern.elevations.push_back((-22.5 + 45.0 * ring / 63.0) * kDegree);
      pattern.columns = 1024;
      pattern.min_range = 0.3;
      pattern.max_range = 120.0;
      break;
    case LidarModel::kPlanarLaser:
      pattern.elevations = {0.0};
      pattern.columns = 1440;
      pattern.min_range = 0.1;
      pattern.max_range = 30.0;
      break;
  }
  return pattern;
}

LidarSimulator::LidarSimulator(LidarSimulatorConfig config, const World& world, const SplineTrajectory& trajectory)
    : config_(std::move(config)), world_(world), trajectory_(trajectory), random_(config_.seed) {
  for (double elevation : config_.pattern.elevations) {
    ring_directions_.emplace_back(std::cos(elevation), 0.0, std::sin(elevation));
  }
}

const LidarWeatherEpisode* LidarSimulator::weather_at(Timestamp time) const {
  for (const LidarWeatherEpisode& episode : config_.weather) {
    if (time >= episode.start && time <= episode.end) return &episode;
  }
  return nullptr;
}

msgs::PointCloudMessage LidarSimulator::measure(Timestamp sweep_start) {
  const LidarPattern& pattern = config_.pattern;
  const int rings = static_cast<int>(ring_directions_.size());
  msgs::PointCloudMessage cloud;
  cloud.timestamp = sweep_start;
  cloud.frame_id = config_.frame_id;
  const std::size_t capacity = static_cast<std::size_t>(pattern.columns) * static_cast<std::size_t>(rings);
  cloud.points.reserve(capacity);
  cloud.intensities.reserve(capacity);
  cloud.ring_ids.reserve(capacity);
  cloud.point_timestamps.reserve(capacity);

  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const double period = 1.0 / config_.rate_hz;
  const LidarWeatherEpisode* weather = weather_at(sweep_start);
  const double max_range = weather != nullptr ? std::min(pattern.max_range, weather->visibility_range) : pattern.max_range;

  // Phase 1 (columns in parallel, deterministic): the noiseless return of every ray.
  struct Return {
    double range = -1.0;  // < 0: nothing within max_range
    float intensity = 0.0F;
    int object_id = kPhantomReturn;
  };
  std::vector<Return> returns(capacity);
  std::vector<Timestamp> column_times(pattern.columns);
  std::vector<char> in_view(pattern.columns, 1);  // inside horizontal_fov
  std::vector<Eigen::Vector3d> directions(capacity);  // sensor frame
  auto cast_columns = [&](const tbb::blocked_range<int>& range) {
    for (int column = range.begin(); column < range.end(); ++column) {
      const Timestamp time = sweep_start + Duration::from_seconds(period * column / pattern.columns);
      column_times[column] = time;
      const SE3 T_world_lidar = trajectory_.sample(time).T_world_body * config_.T_body_lidar;
      const WorldSnapshot snapshot = world_.at(time);
      const double azimuth = std::numbers::pi - 2.0 * std::numbers::pi * column / pattern.columns;
      in_view[column] = std::abs(azimuth) <= 0.5 * pattern.horizontal_fov + 1e-12;
      if (!in_view[column]) continue;
      const double cos_azimuth = std::cos(azimuth), sin_azimuth = std::sin(azimuth);
      int object_hint = -1;  // neighbouring beams mostly see the same object
      for (int ring = 0; ring < rings; ++ring) {
        const std::size_t index = static_cast<std::size_t>(column) * rings + ring;
        const Eigen::Vector3d& beam = ring_directions_[ring];
        directions[index] = Eigen::Vector3d(beam.x() * cos_azimuth, beam.x() * sin_azimuth, beam.z());
        const Eigen::Vector3d direction_world = T_world_lidar.rotation() * directions[index];
        const std::optional<RayHit> hit = snapshot.cast(T_world_lidar.translation(), direction_world, max_range, &object_hint);
        if (!hit) continue;
        const double incidence = std::abs(hit->normal.dot(direction_world));
        const float shade = 0.5F + 0.5F * luminance(hit->material->texture.color(hit->surface_uv.x(), hit->surface_uv.y()));
        returns[index] = {hit->distance, std::clamp(static_cast<float>(hit->material->reflectivity * incidence) * shade, 0.0F, 1.0F), hit->object_id};
      }
    }
  };
  const tbb::blocked_range<int> all_columns(0, pattern.columns, 64);
  if (config_.num_threads == 1 || kUnderThreadSanitizer) {  // core/thread_sanitizer.hpp
    cast_columns(all_columns);
  } else {
    tbb::task_arena arena(config_.num_threads <= 0 ? tbb::task_arena::automatic : config_.num_threads);
    arena.execute([&] { tbb::parallel_for(all_columns, cast_columns); });
  }

  // Phase 2 (in ray order, so the noise draws are reproducible): weather, noise, range limits.
  last_object_ids_.clear();
  last_object_ids_.reserve(capacity);
  for (std::size_t index = 0; index < capacity; ++index) {
    if (!in_view[index / rings]) continue;
    double range = returns[index].range;
    float intensity = returns[index].intensity;
    int object_id = returns[index].object_id;
    if (weather != nullptr && uniform(random_) < weather->phantom_probability) {
      range = pattern.min_range + uniform(random_) * (weather->phantom_max_range - pattern.min_range);
      intensity = kPhantomIntensity;
      object_id = kPhantomReturn;
    } else {
      if (range < 0.0) continue;
      if (weather != nullptr && uniform(random_) < weather->dropout_probability) continue;
      range += normal(random_) * config_.range_noise;
    }
    if (range < pattern.min_range || range > pattern.max_range) continue;
    cloud.points.push_back((directions[index] * range).cast<float>());
    cloud.intensities.push_back(intensity);
    cloud.ring_ids.push_back(static_cast<uint32_t>(index % rings));
    cloud.point_timestamps.push_back(column_times[index / rings]);
    last_object_ids_.push_back(object_id);
  }
  return cloud;
}

}  // namespace hanzo::fusion::sim
