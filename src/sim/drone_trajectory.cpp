#include "hanzo/fusion/sim/drone_trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

namespace hanzo::fusion::sim {
namespace {

double smoothstep(double x) {
  x = std::clamp(x, 0.0, 1.0);
  return x * x * x * (10.0 + x * (-15.0 + 6.0 * x));
}

Eigen::Vector3d position(const DroneTrajectoryConfig& config, double seconds) {
  const double flight = std::max(0.0, seconds - config.still_start);
  const double w = 2.0 * std::numbers::pi / config.period;
  const Eigen::Vector3d figure(config.size.x() * std::sin(w * flight), config.size.y() * std::sin(2.0 * w * flight) / 2.0,
                               config.size.z() * std::sin(3.0 * w * flight));
  return config.center + smoothstep(flight / config.ramp_time) * figure;
}

}  // namespace

Result<SplineTrajectory> make_drone_trajectory(Timestamp start_time, const DroneTrajectoryConfig& config) {
  const std::pair<const char*, double> positive[] = {{"period", config.period},       {"duration", config.duration},
                                                     {"ramp_time", config.ramp_time}, {"yaw_period", config.yaw_period},
                                                     {"knot_spacing", config.knot_spacing}};
  for (const auto& [name, value] : positive) {
    if (!(value > 0.0) || !std::isfinite(value)) return Error{fmt::format("{}: expected a positive number, got {}", name, value), name};
  }
  if (!(config.still_start >= 0.0)) return Error{"still_start: expected >= 0", "still_start"};
  if (!config.center.allFinite() || !config.size.allFinite()) return Error{"center, size: expected finite numbers", "center"};

  const double total = config.still_start + config.duration;
  const auto knots = static_cast<int>(std::ceil(total / config.knot_spacing)) + 3;
  std::vector<SE3> control_poses;
  control_poses.reserve(knots);
  constexpr double h = 1e-3;
  for (int k = 0; k < knots; ++k) {
    const double t = (k - 1) * config.knot_spacing;  // control pose k is centred here
    const Eigen::Vector3d p = position(config, t);
    const Eigen::Vector3d acceleration = (position(config, t + h) - 2.0 * p + position(config, t - h)) / (h * h);
    const Eigen::Vector3d thrust_axis = (acceleration + Eigen::Vector3d(0.0, 0.0, config.gravity)).normalized();
    const double flight = std::max(0.0, t - config.still_start);
    const double yaw = smoothstep(flight / config.ramp_time) * config.yaw_amplitude *
                       std::sin(2.0 * std::numbers::pi * flight / config.yaw_period);
    const Eigen::Vector3d heading(std::cos(yaw), std::sin(yaw), 0.0);
    const Eigen::Vector3d y_axis = thrust_axis.cross(heading).normalized();
    Eigen::Matrix3d rotation;
    rotation << y_axis.cross(thrust_axis), y_axis, thrust_axis;
    control_poses.emplace_back(SO3::from_matrix(rotation), p);
  }
  return SplineTrajectory::create(start_time, Duration::from_seconds(config.knot_spacing), std::move(control_poses));
}

}  // namespace hanzo::fusion::sim
