#include "hanzo/fusion/sim/handheld_trajectory.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

namespace hanzo::fusion::sim {

Result<SplineTrajectory> make_handheld_trajectory(Timestamp start_time, const HandheldTrajectoryConfig& config) {
  if (!(config.look_period > 0.0)) return Error{fmt::format("look_period: expected a positive number, got {}", config.look_period), "look_period"};
  Result<SplineTrajectory> walk = make_ground_trajectory(start_time, config.walk);
  if (!walk) return walk.error();
  const double spacing = config.walk.knot_spacing;
  const auto knots = static_cast<int>(std::ceil((walk->end_time() - start_time).seconds() / spacing)) + 3;
  std::vector<SE3> control_poses;
  control_poses.reserve(knots);
  const double two_pi = 2.0 * std::numbers::pi;
  const double moving_end = (walk->end_time() - start_time).seconds() - config.walk.still_end;
  // The person holds the device still while the walk stands still (a filter's static
  // alignment), starting and stopping to look around over one second (smoothstep).
  const auto looking = [&](double t) {
    const double x = std::clamp(std::min(t - config.walk.still_start, moving_end - t), 0.0, 1.0);
    return x * x * (3.0 - 2.0 * x);
  };
  for (int k = 0; k < knots; ++k) {
    const double t = (k - 1) * spacing;
    const TrajectorySample body = walk->sample(start_time + Duration::from_seconds(t));
    const double pace = std::min(1.0, body.velocity_world.norm() / config.walk.max_speed);
    const double bob = pace * config.bob_amplitude * std::sin(two_pi * config.step_frequency * t);
    const double yaw = looking(t) * config.look_yaw_amplitude * std::sin(two_pi * t / config.look_period);
    const double pitch = looking(t) * config.look_pitch_amplitude * std::sin(two_pi * t / (0.7 * config.look_period));
    const SO3 look = SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), yaw) * SO3::from_axis_angle(Eigen::Vector3d::UnitY(), pitch);
    control_poses.push_back(body.T_world_body * SE3(look, Eigen::Vector3d(0.0, 0.0, bob)));
  }
  return SplineTrajectory::create(start_time, Duration::from_seconds(spacing), std::move(control_poses));
}

}  // namespace hanzo::fusion::sim
