#include "hanzo/fusion/sim/radar_simulator.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <utility>

namespace hanzo::fusion::sim {
namespace {

constexpr float kClutterRcs = -10.0F;  // dBsm

struct Detection {
  double range = 0.0;
  Eigen::Vector3d direction_radar = Eigen::Vector3d::UnitX();  // unit line of sight, radar frame
  double radial_velocity = 0.0;
  double rcs = 0.0;
};

}  // namespace

RadarSimulator::RadarSimulator(RadarSimulatorConfig config, const World& world, const SplineTrajectory& trajectory)
    : config_(std::move(config)), world_(world), trajectory_(trajectory), random_(config_.seed) {}

msgs::RadarMessage RadarSimulator::measure(Timestamp time) {
  const TrajectorySample body = trajectory_.sample(time);
  const SE3 T_world_radar = body.T_world_body * config_.T_body_radar;
  const SO3& R_world_body = body.T_world_body.rotation();
  const Eigen::Vector3d velocity_radar_world =
      body.velocity_world + R_world_body * body.angular_velocity_body.cross(config_.T_body_radar.translation());

  const WorldSnapshot snapshot = world_.at(time);
  // Nearest hit per (object, azimuth cell).
  std::map<std::pair<int, int>, Detection> detections;
  const int columns = std::max(1, static_cast<int>(std::floor(config_.horizontal_fov / config_.azimuth_resolution)) + 1);
  for (int row = 0; row < config_.elevation_rows; ++row) {
    const double elevation = config_.elevation_rows == 1
                                 ? 0.0
                                 : -config_.vertical_fov / 2.0 + config_.vertical_fov * row / (config_.elevation_rows - 1);
    for (int column = 0; column < columns; ++column) {
      const double azimuth = -config_.horizontal_fov / 2.0 + column * config_.azimuth_resolution;
      const Eigen::Vector3d direction_radar(std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth),
                                            std::sin(elevation));
      const Eigen::Vector3d direction_world = T_world_radar.rotation() * direction_radar;
      const std::optional<RayHit> hit = snapshot.cast(T_world_radar.translation(), direction_world, config_.max_range);
      if (!hit || hit->object_id < 0) continue;
      const auto cell = static_cast<int>(std::floor((azimuth + config_.horizontal_fov / 2.0) / config_.cluster_azimuth));
      auto [entry, inserted] = detections.try_emplace({hit->object_id, cell});
      if (!inserted && entry->second.range <= hit->distance) continue;
      entry->second = {hit->distance, direction_radar, (hit->object_velocity - velocity_radar_world).dot(direction_world),
                       hit->material->radar_cross_section};
    }
  }

  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  msgs::RadarMessage message;
  message.timestamp = time;
  message.frame_id = config_.frame_id;
  for (const auto& [key, detection] : detections) {
    const Eigen::Vector3d& d = detection.direction_radar;
    msgs::RadarTarget target;
    target.range = static_cast<float>(std::max(0.0, detection.range + config_.range_noise * normal(random_)));
    target.azimuth = static_cast<float>(std::remainder(std::atan2(d.y(), d.x()) + config_.azimuth_noise * normal(random_),
                                                       2.0 * std::numbers::pi));
    target.elevation = static_cast<float>(std::clamp(std::asin(std::clamp(d.z(), -1.0, 1.0)) + config_.elevation_noise * normal(random_),
                                                     -std::numbers::pi / 2.0, std::numbers::pi / 2.0));
    target.radial_velocity = static_cast<float>(detection.radial_velocity + config_.velocity_noise * normal(random_));
    target.rcs = static_cast<float>(detection.rcs + config_.rcs_noise * normal(random_));
    message.targets.push_back(target);
  }
  std::poisson_distribution<int> clutter_count(config_.clutter_rate);
  const int clutter = config_.clutter_rate > 0.0 ? clutter_count(random_) : 0;
  for (int i = 0; i < clutter; ++i) {
    msgs::RadarTarget target;
    target.range = static_cast<float>(uniform(random_) * config_.max_range);
    target.azimuth = static_cast<float>((uniform(random_) - 0.5) * config_.horizontal_fov);
    target.elevation = static_cast<float>((uniform(random_) - 0.5) * config_.vertical_fov);
    target.radial_velocity = static_cast<float>((uniform(random_) - 0.5) * 20.0);
    target.rcs = kClutterRcs + static_cast<float>(config_.rcs_noise * normal(random_));
    message.targets.push_back(target);
  }
  return message;
}

}  // namespace hanzo::fusion::sim
