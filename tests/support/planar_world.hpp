#pragma once
// A simulated planar world for 2D laser tests: line-segment walls and an exact ray caster.

#include <algorithm>
#include <cmath>
#include <vector>

#include "hanzo/fusion/core/se2.hpp"
#include "hanzo/fusion/lidar/planar_icp.hpp"

namespace hanzo::fusion::test_support {

struct Segment {
  Eigen::Vector2d a, b;
};

// A 12 x 8 m room with an inner wall stub and four square pillars (corners everywhere).
inline std::vector<Segment> room() {
  std::vector<Segment> walls = {{{0, 0}, {12, 0}}, {{12, 0}, {12, 8}}, {{12, 8}, {0, 8}}, {{0, 8}, {0, 0}}, {{6, 0}, {6, 3}}};
  for (const Eigen::Vector2d& centre : {Eigen::Vector2d(3, 5), Eigen::Vector2d(9, 5.5), Eigen::Vector2d(8.5, 2), Eigen::Vector2d(2, 2)}) {
    const double h = 0.25;
    const Eigen::Vector2d c00 = centre + Eigen::Vector2d(-h, -h), c10 = centre + Eigen::Vector2d(h, -h);
    const Eigen::Vector2d c11 = centre + Eigen::Vector2d(h, h), c01 = centre + Eigen::Vector2d(-h, h);
    walls.insert(walls.end(), {{c00, c10}, {c10, c11}, {c11, c01}, {c01, c00}});
  }
  return walls;
}

// A corridor along x from -half_length to +half_length, 2 m wide: walls only, or with a 1 m
// wide, 0.3 m deep door recess in the left wall every 6 m. Seen with an 8 m range the ends stay
// out of sight.
inline std::vector<Segment> corridor(bool with_doors, double half_length = 20.0) {
  std::vector<Segment> walls = {{{-half_length, -1}, {half_length, -1}}};
  if (!with_doors) {
    walls.push_back({{-half_length, 1}, {half_length, 1}});
    return walls;
  }
  double x = -half_length;
  for (double door = -half_length + 2; door + 1 <= half_length; door += 6) {
    walls.push_back({{x, 1}, {door, 1}});
    walls.push_back({{door, 1}, {door, 1.3}});
    walls.push_back({{door, 1.3}, {door + 1, 1.3}});
    walls.push_back({{door + 1, 1.3}, {door + 1, 1}});
    x = door + 1;
  }
  walls.push_back({{x, 1}, {half_length, 1}});
  return walls;
}

// A 360-beam, 270 deg scan from `pose` (points in the laser frame, ranges below max_range).
inline lidar::PlanarPoints cast_scan(const std::vector<Segment>& walls, const SE2& pose, double max_range = 30.0) {
  lidar::PlanarPoints points;
  for (int beam = 0; beam < 360; ++beam) {
    const double angle = (-135.0 + beam * 0.75) * M_PI / 180.0;
    const Eigen::Vector2d direction = pose.rotation_matrix() * Eigen::Vector2d(std::cos(angle), std::sin(angle));
    double nearest = max_range;
    for (const Segment& wall : walls) {
      const Eigen::Vector2d edge = wall.b - wall.a;
      const double denominator = direction.x() * edge.y() - direction.y() * edge.x();
      if (std::abs(denominator) < 1e-12) continue;
      const Eigen::Vector2d offset = wall.a - pose.translation();
      const double range = (offset.x() * edge.y() - offset.y() * edge.x()) / denominator;
      const double along = (offset.x() * direction.y() - offset.y() * direction.x()) / denominator;
      if (range > 0.05 && along >= 0 && along <= 1) nearest = std::min(nearest, range);
    }
    if (nearest < max_range) points.emplace_back(nearest * std::cos(angle), nearest * std::sin(angle));
  }
  return points;
}

}  // namespace hanzo::fusion::test_support
