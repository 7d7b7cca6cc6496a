#include "hanzo/fusion/sim/stations_trajectory.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace hanzo::fusion::sim {
namespace {

SE3 station_pose(const StationPose& station) {
  const SO3 rotation = SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), station.roll_pitch_yaw.z()) *
                       SO3::from_axis_angle(Eigen::Vector3d::UnitY(), station.roll_pitch_yaw.y()) *
                       SO3::from_axis_angle(Eigen::Vector3d::UnitX(), station.roll_pitch_yaw.x());
  return SE3(rotation, station.position);
}

}  // namespace

Result<SplineTrajectory> make_stations_trajectory(Timestamp start_time, const StationsTrajectoryConfig& config) {
  if (config.stations.empty()) return Error{"stations: expected at least one station", "stations"};
  for (std::size_t i = 0; i < config.stations.size(); ++i) {
    if (!config.stations[i].position.allFinite() || !config.stations[i].roll_pitch_yaw.allFinite()) {
      return Error{fmt::format("stations[{}]: not finite", i), "stations"};
    }
  }
  if (!(config.knot_spacing > 0.0)) return Error{fmt::format("knot_spacing: expected > 0, got {}", config.knot_spacing), "knot_spacing"};
  if (!(config.move > 0.0)) return Error{fmt::format("move: expected > 0 s, got {}", config.move), "move"};
  if (!(config.hold >= 4.0 * config.knot_spacing)) {
    return Error{fmt::format("hold: expected >= 4 knot spacings ({} s), got {} s", 4.0 * config.knot_spacing, config.hold), "hold"};
  }
  std::vector<SE3> poses;
  for (const StationPose& station : config.stations) poses.push_back(station_pose(station));
  const double leg = config.hold + config.move;
  const double total = static_cast<double>(poses.size()) * config.hold + static_cast<double>(poses.size() - 1) * config.move;
  // The pose at time t: held at station i during [i leg, i leg + hold], eased towards i + 1 after.
  const auto pose_at = [&](double t) {
    const double clamped = std::clamp(t, 0.0, total);
    const auto i = std::min(static_cast<std::size_t>(clamped / leg), poses.size() - 1);
    const double x = std::clamp((clamped - static_cast<double>(i) * leg - config.hold) / config.move, 0.0, 1.0);
    if (x <= 0.0 || i + 1 >= poses.size()) return poses[i];
    const double s = x * x * (3.0 - 2.0 * x);
    const SE3& a = poses[i];
    const SE3& b = poses[i + 1];
    return SE3(SO3::interpolate(a.rotation(), b.rotation(), s), (1.0 - s) * a.translation() + s * b.translation());
  };
  // Segment k of the spline spans [k, k + 1) knot spacings and uses control poses k..k+3; the
  // control pose k + 1 sits at the segment's start, so control pose k is at (k - 1) spacings.
  const auto knots = static_cast<int>(std::ceil(total / config.knot_spacing)) + 3;
  std::vector<SE3> control_poses;
  control_poses.reserve(knots);
  for (int k = 0; k < knots; ++k) control_poses.push_back(pose_at((k - 1) * config.knot_spacing));
  return SplineTrajectory::create(start_time, Duration::from_seconds(config.knot_spacing), std::move(control_poses));
}

}  // namespace hanzo::fusion::sim
