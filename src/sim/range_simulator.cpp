#include "hanzo/fusion/sim/range_simulator.hpp"

#include <cmath>
#include <limits>
#include <numbers>
#include <utility>

namespace hanzo::fusion::sim {

RangeSimulator::RangeSimulator(RangeSimulatorConfig config, const World& world, const SplineTrajectory& trajectory)
    : config_(std::move(config)), world_(world), trajectory_(trajectory), random_(config_.seed) {}

msgs::RangeMessage RangeSimulator::measure(Timestamp time) {
  const SE3 T_world_range = trajectory_.sample(time).T_world_body * config_.T_body_range;
  const WorldSnapshot snapshot = world_.at(time);
  constexpr int kRingRays = 8;
  double nearest = std::numeric_limits<double>::infinity();
  const auto cast = [&](double off_axis, double around) {
    const Eigen::Vector3d direction(std::cos(off_axis), std::sin(off_axis) * std::cos(around), std::sin(off_axis) * std::sin(around));
    const std::optional<RayHit> hit = snapshot.cast(T_world_range.translation(), T_world_range.rotation() * direction, config_.max_range);
    if (hit) nearest = std::min(nearest, hit->distance);
  };
  cast(0.0, 0.0);
  for (const double ring : {0.25, 0.5}) {
    for (int k = 0; k < kRingRays; ++k) cast(ring * config_.field_of_view, 2.0 * std::numbers::pi * k / kRingRays);
  }
  msgs::RangeMessage message;
  message.timestamp = time;
  message.frame_id = config_.frame_id;
  message.radiation = config_.radiation;
  message.field_of_view = static_cast<float>(config_.field_of_view);
  message.min_range = static_cast<float>(config_.min_range);
  message.max_range = static_cast<float>(config_.max_range);
  message.variance = static_cast<float>(config_.range_noise * config_.range_noise);
  if (std::isfinite(nearest)) nearest += std::normal_distribution<double>(0.0, config_.range_noise)(random_);
  if (nearest > config_.max_range) {
    message.range = std::numeric_limits<float>::infinity();
  } else if (nearest < config_.min_range) {
    message.range = -std::numeric_limits<float>::infinity();
  } else {
    message.range = static_cast<float>(nearest);
  }
  return message;
}

}  // namespace hanzo::fusion::sim
