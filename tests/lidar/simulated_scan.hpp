#pragma once
// Static LiDAR scans of a simulated scene with exact poses, for registration tests.

#include <cmath>
#include <random>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/sim/world.hpp"

namespace hanzo::fusion::testing_support {

/// A 40 m x 30 m yard: ground, four walls, boxes at several yaws and poles, so that every
/// direction of motion is constrained.
inline sim::World registration_world() {
  sim::WorldDescription description;
  const auto box = [](double x, double y, double z, double hx, double hy, double hz, double yaw) {
    sim::Box b;
    b.center = {x, y, z};
    b.half_size = {hx, hy, hz};
    b.yaw = yaw;
    return b;
  };
  description.boxes = {box(20, 0, 2, 0.3, 15, 2, 0),       box(-20, 0, 2, 0.3, 15, 2, 0),
                       box(0, 15, 2, 20, 0.3, 2, 0),       box(0, -15, 2, 20, 0.3, 2, 0),
                       box(6, 4, 1, 1.5, 0.8, 1, 0.4),     box(-5, -6, 1.5, 2, 1, 1.5, -0.7),
                       box(9, -7, 0.75, 0.75, 2.5, 0.75, 1.1), box(-9, 7, 2.5, 1, 1, 2.5, 0.2)};
  for (int i = 0; i < 6; ++i) {
    sim::Cylinder pole;
    pole.base_center = {-12.0 + 5.0 * i, (i % 2 ? 9.0 : -10.0), 0.0};
    pole.radius = 0.15;
    pole.height = 4.0;
    description.cylinders.push_back(pole);
  }
  return sim::World(description);
}

/// A static 32-ring (-22.5..+22.5 deg) x 900-column scan from T_world_sensor, in the sensor
/// frame, ranges disturbed by N(0, range_noise^2).
inline cloud::PointCloud scan(const sim::World& world, const SE3& T_world_sensor, double range_noise, uint32_t seed) {
  std::mt19937 random(seed);
  std::normal_distribution<double> noise(0.0, range_noise);
  cloud::PointCloud out;
  const auto snapshot = world.at(Timestamp());
  for (int column = 0; column < 900; ++column) {
    const double azimuth = 2.0 * M_PI * column / 900.0;
    for (int ring = 0; ring < 32; ++ring) {
      const double elevation = (-22.5 + 45.0 * ring / 31.0) * M_PI / 180.0;
      const Eigen::Vector3d direction(std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth),
                                      std::sin(elevation));
      const auto hit = snapshot.cast(T_world_sensor.translation(), T_world_sensor.rotation() * direction, 60.0);
      if (!hit) continue;
      const double range = hit->distance + noise(random);
      out.positions.push_back((direction * range).cast<float>());
      out.rings.push_back(static_cast<uint16_t>(ring));
    }
  }
  return out;
}

}  // namespace hanzo::fusion::testing_support
