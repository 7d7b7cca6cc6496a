#include "hanzo/fusion/sim/ground_path.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

namespace hanzo::fusion::sim {
namespace {

constexpr double kPathStep = 0.02;  // metres between densified path points
constexpr double kMaxTurn = 170.0 * std::numbers::pi / 180.0;  // radians at one corner

struct PathPoint {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  double yaw = 0.0;        // unwrapped
  double curvature = 0.0;  // 1/m, absolute
};

Eigen::Vector2d xy(const Eigen::Vector3d& p) { return p.head<2>(); }

// The polyline with every interior corner replaced by an arc, sampled every kPathStep metres.
std::vector<PathPoint> densify(const std::vector<Eigen::Vector3d>& polyline, double corner_radius) {
  const std::size_t n = polyline.size();
  // Trim length at each corner (tangent point distance) and the arc radius actually used.
  std::vector<double> trim(n, 0.0), radius(n, 0.0), turn(n, 0.0);
  for (std::size_t j = 1; j + 1 < n; ++j) {
    const Eigen::Vector2d in = xy(polyline[j] - polyline[j - 1]), out = xy(polyline[j + 1] - polyline[j]);
    turn[j] = std::atan2(in.x() * out.y() - in.y() * out.x(), in.dot(out));
    if (std::abs(turn[j]) < 1e-9) continue;
    const double half_tangent = std::tan(std::abs(turn[j]) / 2.0);
    trim[j] = std::min(corner_radius * half_tangent, 0.5 * std::min(in.norm(), out.norm()));
    radius[j] = trim[j] / half_tangent;
  }
  std::vector<PathPoint> points;
  double yaw = std::atan2(polyline[1].y() - polyline[0].y(), polyline[1].x() - polyline[0].x());
  auto append = [&](const Eigen::Vector3d& position, double curvature) { points.push_back({position, yaw, curvature}); };
  for (std::size_t j = 0; j + 1 < n; ++j) {
    const Eigen::Vector3d a = polyline[j], b = polyline[j + 1];
    const Eigen::Vector2d direction = xy(b - a).normalized();
    const double length = xy(b - a).norm();
    if (j > 0) yaw += std::remainder(std::atan2(direction.y(), direction.x()) - std::remainder(yaw, 2.0 * std::numbers::pi), 2.0 * std::numbers::pi);
    const double from = trim[j], to = length - trim[j + 1];
    const int steps = std::max(1, static_cast<int>(std::ceil((to - from) / kPathStep)));
    for (int step = 0; step < steps; ++step) {
      const double s = from + (to - from) * step / steps;
      append(a + (b - a) * (s / length), 0.0);
    }
    if (j + 2 < n && radius[j + 1] > 0.0) {  // the arc around corner j + 1
      const double sign = turn[j + 1] > 0.0 ? 1.0 : -1.0;
      const Eigen::Vector3d tangent_point = b - Eigen::Vector3d(direction.x(), direction.y(), 0.0) * trim[j + 1];
      const Eigen::Vector2d center = xy(tangent_point) + sign * radius[j + 1] * Eigen::Vector2d(-direction.y(), direction.x());
      const Eigen::Vector2d start_offset = xy(tangent_point) - center;
      const double arc_length = radius[j + 1] * std::abs(turn[j + 1]);
      const int arc_steps = std::max(1, static_cast<int>(std::ceil(arc_length / kPathStep)));
      const double start_yaw = yaw;
      for (int step = 0; step < arc_steps; ++step) {
        const double angle = turn[j + 1] * step / arc_steps;
        const Eigen::Vector2d offset(std::cos(angle) * start_offset.x() - std::sin(angle) * start_offset.y(),
                                     std::sin(angle) * start_offset.x() + std::cos(angle) * start_offset.y());
        yaw = start_yaw + angle;
        append({center.x() + offset.x(), center.y() + offset.y(), b.z()}, 1.0 / radius[j + 1]);
      }
      yaw = start_yaw + turn[j + 1];
    }
  }
  append(polyline.back(), 0.0);
  return points;
}

Status check(const GroundPathConfig& config) {
  const std::size_t minimum = config.closed ? 3 : 2;
  if (config.waypoints.size() < minimum) {
    return Error{fmt::format("waypoints: need at least {} for a{} path, got {}", minimum, config.closed ? " closed" : "n open",
                             config.waypoints.size()), "waypoints"};
  }
  for (std::size_t i = 0; i < config.waypoints.size(); ++i) {
    if (!config.waypoints[i].allFinite()) return Error{fmt::format("waypoints[{}]: not finite", i), "waypoints"};
    const Eigen::Vector3d& next = config.waypoints[(i + 1) % config.waypoints.size()];
    if ((i + 1 < config.waypoints.size() || config.closed) && xy(next - config.waypoints[i]).norm() < 1e-6) {
      return Error{fmt::format("waypoints[{}]: same x, y as the waypoint before it", (i + 1) % config.waypoints.size()), "waypoints"};
    }
  }
  // A vehicle cannot reverse on the spot: every corner it drives through must turn less than
  // kMaxTurn (interior corners; on a closed path every corner).
  const std::size_t n = config.waypoints.size();
  for (std::size_t j = config.closed ? 0 : 1; j < (config.closed ? n : n - 1); ++j) {
    const Eigen::Vector2d in = xy(config.waypoints[j] - config.waypoints[(j + n - 1) % n]);
    const Eigen::Vector2d out = xy(config.waypoints[(j + 1) % n] - config.waypoints[j]);
    const double turn = std::abs(std::atan2(in.x() * out.y() - in.y() * out.x(), in.dot(out)));
    if (turn > kMaxTurn) {
      return Error{fmt::format("waypoints[{}]: turns {:.0f} deg, more than {:.0f}: add a waypoint to drive the turn", j,
                               turn * 180.0 / std::numbers::pi, kMaxTurn * 180.0 / std::numbers::pi),
                   "waypoints"};
    }
  }
  const std::pair<const char*, double> positive[] = {
      {"corner_radius", config.corner_radius},       {"max_speed", config.max_speed},
      {"max_acceleration", config.max_acceleration}, {"max_lateral_acceleration", config.max_lateral_acceleration},
      {"knot_spacing", config.knot_spacing}};
  for (const auto& [name, value] : positive) {
    if (!(value > 0.0) || !std::isfinite(value)) return Error{fmt::format("{}: expected a positive number, got {}", name, value), name};
  }
  if (!(config.still_start >= 0.0) || !(config.still_end >= 0.0)) return Error{"still_start, still_end: expected >= 0", "still_start"};
  if (config.laps < 1) return Error{fmt::format("laps: expected >= 1, got {}", config.laps), "laps"};
  return ok_status();
}

}  // namespace

Result<SplineTrajectory> make_ground_trajectory(Timestamp start_time, const GroundPathConfig& config) {
  HANZO_RETURN_IF_ERROR(check(config));
  std::vector<Eigen::Vector3d> polyline = config.waypoints;
  if (config.closed) {
    polyline.clear();
    for (int lap = 0; lap < config.laps; ++lap) polyline.insert(polyline.end(), config.waypoints.begin(), config.waypoints.end());
    polyline.push_back(config.waypoints.front());
  }
  const std::vector<PathPoint> path = densify(polyline, config.corner_radius);

  // Speed limits per point, then the forward (acceleration) and backward (braking) passes.
  const std::size_t n = path.size();
  std::vector<double> step(n, 0.0), speed(n, 0.0);
  for (std::size_t i = 1; i < n; ++i) step[i] = (path[i].position - path[i - 1].position).norm();
  for (std::size_t i = 0; i < n; ++i) {
    speed[i] = path[i].curvature > 0.0 ? std::min(config.max_speed, std::sqrt(config.max_lateral_acceleration / path[i].curvature))
                                       : config.max_speed;
  }
  speed.front() = speed.back() = 0.0;
  for (std::size_t i = 1; i < n; ++i) speed[i] = std::min(speed[i], std::sqrt(speed[i - 1] * speed[i - 1] + 2.0 * config.max_acceleration * step[i]));
  for (std::size_t i = n - 1; i-- > 0;) speed[i] = std::min(speed[i], std::sqrt(speed[i + 1] * speed[i + 1] + 2.0 * config.max_acceleration * step[i + 1]));
  std::vector<double> time(n, 0.0);  // seconds since the vehicle starts moving
  for (std::size_t i = 1; i < n; ++i) {
    const double mean_speed = 0.5 * (speed[i - 1] + speed[i]);
    time[i] = time[i - 1] + (mean_speed > 0.0 ? step[i] / mean_speed : 0.0);
  }

  auto pose_at = [&](double seconds) {
    const double t = std::clamp(seconds - config.still_start, 0.0, time.back());
    const std::size_t upper = std::min<std::size_t>(n - 1, std::max<std::size_t>(1, std::upper_bound(time.begin(), time.end(), t) - time.begin()));
    const std::size_t lower = upper - 1;
    const double span = time[upper] - time[lower];
    const double f = span > 0.0 ? (t - time[lower]) / span : 0.0;
    const Eigen::Vector3d position = path[lower].position + f * (path[upper].position - path[lower].position);
    const double yaw = path[lower].yaw + f * (path[upper].yaw - path[lower].yaw);
    return SE3(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), yaw), position);
  };
  const double duration = config.still_start + time.back() + config.still_end;
  const auto knots = static_cast<int>(std::ceil(duration / config.knot_spacing)) + 3;
  std::vector<SE3> control_poses;
  control_poses.reserve(knots);
  // Control pose k is centred on start_time + (k - 1) * knot_spacing (a cubic B-spline's
  // segment blends poses k-1..k+2 around pose k).
  for (int k = 0; k < knots; ++k) control_poses.push_back(pose_at((k - 1) * config.knot_spacing));
  return SplineTrajectory::create(start_time, Duration::from_seconds(config.knot_spacing), std::move(control_poses));
}

}  // namespace hanzo::fusion::sim
