// The LiDAR simulator: ranges against analytic distances to known planes, per-point
// timestamps, motion distortion consistent with the trajectory, and the weather faults.

#include <algorithm>
#include <cmath>
#include <map>
#include <string>

#include <gtest/gtest.h>

#include "hanzo/fusion/msgs/validate.hpp"
#include "hanzo/fusion/sim/lidar_simulator.hpp"

namespace hanzo::fusion::sim {
namespace {

const Timestamp kStart = Timestamp::from_nanoseconds(1'700'000'000'000'000'000);
constexpr double kSensorHeight = 1.5;
constexpr double kWallX = 10.0;

// Ground z = 0 and a wall whose face is the plane x = kWallX (|y| < 50, z < 10).
World plane_world() {
  WorldDescription description;
  Box wall;
  wall.center = {kWallX + 0.5, 0.0, 5.0};
  wall.half_size = {0.5, 50.0, 5.0};
  wall.material.reflectivity = 0.8;
  description.boxes.push_back(wall);
  return World(description);
}

// Constant velocity along +x (a B-spline through collinear, evenly spaced poses is exactly linear).
SplineTrajectory straight_trajectory(double speed) {
  std::vector<SE3> poses;
  for (int i = 0; i < 8; ++i) poses.emplace_back(SO3(), Eigen::Vector3d(speed * 0.5 * (i - 1), 0.0, kSensorHeight));
  return *SplineTrajectory::create(kStart, Duration::from_milliseconds(500), poses);
}

// Distance along a unit ray from (x0, 0, kSensorHeight) to the nearer of the two planes.
double analytic_range(const Eigen::Vector3d& direction, double x0) {
  double nearest = 1e9;
  if (direction.z() < 0.0) nearest = std::min(nearest, kSensorHeight / -direction.z());
  if (direction.x() > 0.0) {
    const double t = (kWallX - x0) / direction.x();
    const Eigen::Vector3d p = Eigen::Vector3d(x0, 0.0, kSensorHeight) + t * direction;
    if (p.z() >= 0.0 && p.z() <= 10.0 && std::abs(p.y()) <= 50.0) nearest = std::min(nearest, t);
  }
  return nearest;
}

TEST(LidarSimulator, RangesEqualAnalyticDistancesToKnownPlanes) {
  const World world = plane_world();
  const SplineTrajectory trajectory = straight_trajectory(0.0);
  for (LidarModel model : {LidarModel::kVelodyneVlp16, LidarModel::kVelodyneHdl64, LidarModel::kOusterOs1_64}) {
    LidarSimulatorConfig config;
    config.pattern = LidarPattern::preset(model);
    config.range_noise = 0.0;
    LidarSimulator lidar(config, world, trajectory);
    const msgs::PointCloudMessage cloud = lidar.measure(kStart + Duration::from_seconds(1.0));
    ASSERT_TRUE(msgs::validate(cloud)) << to_string(model);
    ASSERT_GT(cloud.points.size(), 1000U);
    int wall_points = 0;
    for (const Eigen::Vector3f& point : cloud.points) {
      const Eigen::Vector3d p = point.cast<double>();
      const double expected = analytic_range(p.normalized(), 0.0);
      ASSERT_NEAR(p.norm(), expected, 2e-5 * expected) << to_string(model);
      if (std::abs(p.x() - kWallX) < 1e-3) ++wall_points;
    }
    EXPECT_GT(wall_points, 100) << to_string(model);
    // Every ring is present and every point's ring id is valid.
    for (uint32_t ring : cloud.ring_ids) ASSERT_LT(ring, config.pattern.elevations.size());
  }
}

TEST(LidarSimulator, AHorizontalFieldOfViewKeepsTheReturnsInsideIt) {
  const World world = plane_world();
  const SplineTrajectory trajectory = straight_trajectory(0.0);
  LidarSimulatorConfig config;
  config.range_noise = 0.0;
  const std::size_t all_round = LidarSimulator(config, world, trajectory).measure(kStart + Duration::from_seconds(1.0)).points.size();
  config.pattern.horizontal_fov = M_PI / 2.0;  // 45 degrees either side of the x axis
  LidarSimulator lidar(config, world, trajectory);
  const msgs::PointCloudMessage cloud = lidar.measure(kStart + Duration::from_seconds(1.0));
  ASSERT_TRUE(msgs::validate(cloud));
  for (const Eigen::Vector3f& point : cloud.points) ASSERT_LE(std::abs(std::atan2(point.y(), point.x())), M_PI / 4.0 + 1e-3);
  // A quarter of the ground (and all of the wall, ahead) is left.
  EXPECT_GT(cloud.points.size(), all_round / 5);
  EXPECT_LT(cloud.points.size(), all_round / 2);
}

TEST(LidarSimulator, PointTimesAreMonotonicAndDistortionFollowsTheMotion) {
  const World world = plane_world();
  const double speed = 10.0;  // m/s towards the wall: 1 m of motion during a sweep
  const SplineTrajectory trajectory = straight_trajectory(speed);
  LidarSimulatorConfig config;
  config.range_noise = 0.0;
  LidarSimulator lidar(config, world, trajectory);
  const Timestamp sweep_start = kStart + Duration::from_seconds(0.2);
  const msgs::PointCloudMessage cloud = lidar.measure(sweep_start);
  ASSERT_EQ(cloud.point_timestamps.size(), cloud.points.size());
  EXPECT_EQ(cloud.timestamp, sweep_start);
  for (std::size_t i = 1; i < cloud.point_timestamps.size(); ++i) {
    ASSERT_LE(cloud.point_timestamps[i - 1], cloud.point_timestamps[i]) << i;
  }
  EXPECT_GE(cloud.point_timestamps.front(), sweep_start);
  EXPECT_LT(cloud.point_timestamps.back(), sweep_start + Duration::from_milliseconds(100));
  // Each point, placed with the sensor pose at its own time, lies on the ground or the wall;
  // placed with the sweep-start pose (no deskewing), wall points are off by the distance travelled.
  double largest_skew = 0.0;
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    const Eigen::Vector3d p = cloud.points[i].cast<double>();
    const double x0 = trajectory.sample(cloud.point_timestamps[i]).T_world_body.translation().x();
    ASSERT_NEAR(p.norm(), analytic_range(p.normalized(), x0), 1e-4) << i;
    if (std::abs(p.x() + x0 - kWallX) < 1e-3) largest_skew = std::max(largest_skew, std::abs(p.x() - (kWallX - 2.0)));
  }
  EXPECT_GT(largest_skew, 0.5);  // x0 ran from 2.0 to 3.0 over the sweep
}

TEST(LidarSimulator, RainDropsReturnsAddsNearPhantomsAndShortensRange) {
  const World world = plane_world();
  const SplineTrajectory trajectory = straight_trajectory(0.0);
  LidarSimulatorConfig config;
  config.range_noise = 0.0;
  const Timestamp rain_start = kStart + Duration::from_seconds(1.0);
  config.weather.push_back({rain_start, rain_start + Duration::from_seconds(1.0), 0.3, 0.05, 3.0, 9.0});
  LidarSimulator lidar(config, world, trajectory);
  const msgs::PointCloudMessage dry = lidar.measure(kStart + Duration::from_seconds(0.5));
  const msgs::PointCloudMessage wet = lidar.measure(rain_start + Duration::from_milliseconds(100));
  EXPECT_LT(wet.points.size(), dry.points.size() * 0.8);
  std::size_t phantoms = 0, beyond_visibility = 0;
  for (std::size_t i = 0; i < wet.points.size(); ++i) {
    const double range = wet.points[i].norm();
    if (range > 9.0 + 1e-6) ++beyond_visibility;
    if (std::abs(range - analytic_range(wet.points[i].cast<double>().normalized(), 0.0)) > 1e-3) {
      ++phantoms;
      EXPECT_LE(range, 3.0 + 1e-6);
    }
  }
  EXPECT_EQ(beyond_visibility, 0U);
  EXPECT_NEAR(static_cast<double>(phantoms) / (1800 * 16), 0.05, 0.01);
  // The wall at 10 m is beyond the 9 m visibility: only ground and phantoms remain.
  for (const Eigen::Vector3f& point : wet.points) EXPECT_LT(point.x(), kWallX - 0.5);
  // The per-point truth calls the phantoms so.
  ASSERT_EQ(lidar.last_object_ids().size(), wet.points.size());
  EXPECT_EQ(static_cast<std::size_t>(std::count(lidar.last_object_ids().begin(), lidar.last_object_ids().end(), kPhantomReturn)), phantoms);
}

// Per-point ground truth: each return's object (ground, the wall, a person walking across in
// front of it), its class and whether it moves, checked against the geometry.
TEST(LidarSimulator, EachPointSaysWhatItHit) {
  WorldDescription description;
  Box wall;
  wall.center = {kWallX + 0.5, 0.0, 5.0};
  wall.half_size = {0.5, 50.0, 5.0};
  wall.class_name = "wall";
  description.boxes.push_back(wall);
  MovingBox person;
  person.box.half_size = {0.3, 0.3, 0.9};
  person.path = {Eigen::Vector2d(5.0, -4.0), Eigen::Vector2d(5.0, 4.0)};
  person.speed = 1.5;
  person.start_time = kStart;
  description.moving_boxes.push_back(person);
  const World world(description);
  const SplineTrajectory trajectory = straight_trajectory(0.0);
  LidarSimulatorConfig config;
  config.range_noise = 0.0;
  LidarSimulator lidar(config, world, trajectory);
  const Timestamp sweep = kStart + Duration::from_seconds(2.6);  // the person near y = 0
  const msgs::PointCloudMessage cloud = lidar.measure(sweep);
  const std::vector<int>& objects = lidar.last_object_ids();
  ASSERT_EQ(objects.size(), cloud.points.size());
  std::map<std::string, int> counts;
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    const Eigen::Vector3d world_point = cloud.points[i].cast<double>() + Eigen::Vector3d(0.0, 0.0, kSensorHeight);  // the sensor stands at x = 0
    ++counts[world.object_class(objects[i])];
    if (objects[i] == -1) {
      EXPECT_NEAR(world_point.z(), 0.0, 1e-3);
    }
    if (objects[i] == 0) {
      EXPECT_NEAR(world_point.x(), kWallX, 1e-3);
    }
    if (world.is_moving(objects[i])) {
      const Eigen::Vector3d centre = person.center_at(cloud.point_timestamps[i], 0.0);
      EXPECT_LE((world_point - centre).cwiseAbs().maxCoeff(), 0.9 + 1e-3);
    }
  }
  EXPECT_GT(counts["ground"], 1000);
  EXPECT_GT(counts["wall"], 1000);
  EXPECT_GT(counts["person"], 20);
  EXPECT_EQ(counts.size(), 3U);
  EXPECT_FALSE(world.is_moving(0));
  EXPECT_FALSE(world.is_moving(-1));
}

TEST(LidarSimulator, PatternsAndNames) {
  EXPECT_EQ(LidarPattern::preset(LidarModel::kVelodyneVlp16).elevations.size(), 16U);
  const LidarPattern hdl = LidarPattern::preset(LidarModel::kVelodyneHdl64);
  ASSERT_EQ(hdl.elevations.size(), 64U);
  for (std::size_t i = 1; i < hdl.elevations.size(); ++i) EXPECT_LT(hdl.elevations[i - 1], hdl.elevations[i]);
  EXPECT_NEAR(hdl.elevations.back(), 2.0 * M_PI / 180.0, 1e-12);
  EXPECT_EQ(lidar_model_from_string("ouster_os1_64"), LidarModel::kOusterOs1_64);
  EXPECT_FALSE(lidar_model_from_string("livox"));
}

}  // namespace
}  // namespace hanzo::fusion::sim
