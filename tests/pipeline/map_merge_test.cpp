// Maps of two sessions joined without an initial guess (pipeline/map_merge.hpp): two patrols of
// the simulated warehouse (different sensor noise), the second map moved far away and turned so
// that no guess could help; where it belongs is found within 0.1 m and half a degree. A map of
// another place (a room of pillars the warehouse does not have) is refused with the reason.

#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/pipeline/map_merge.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "scenario_replay.hpp"

namespace hanzo::fusion::pipeline {
namespace {

msgs::FusionMap patrol_map(uint64_t seed) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/warehouse_robot.yaml").value();
  scenario.duration = 25.0;
  scenario.num_threads = 0;
  sim::set_seed(scenario, seed);
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& sensor) { return sensor.name != "imu" && sensor.name != "lidar" && sensor.name != "wheels"; });
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  auto session = Session::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario)).value();
  (void)testing::replay(*simulation, *session);
  msgs::FusionMap map = session->map();
  map.map_id = "patrol" + std::to_string(seed);
  return map;
}

msgs::FusionMap moved(msgs::FusionMap map, const SE3& T_new_old) {
  for (Eigen::Vector3f& point : map.points->points) point = (T_new_old * point.cast<double>()).cast<float>();
  return map;
}

TEST(MapMerge, TwoPatrolsJoinWithoutAGuessAndAnotherPlaceIsRefused) {
  const msgs::FusionMap a = patrol_map(1);
  const msgs::FusionMap b = patrol_map(2);
  ASSERT_TRUE(a.points && b.points);
  const SE3 T_moved_b(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 1.2), Eigen::Vector3d(37.0, -21.0, 0.4));
  MapMergeConfig config;
  config.odometry.map.voxel_size = 0.5;  // indoors (map merge --indoor)
  config.odometry.source_voxel_size = 0.25;
  const MapMergeResult merged = merge_maps(a, moved(b, T_moved_b), config).value();
  // Both sessions' worlds are their start pose: T_a_b is the inverse of the move.
  const SE3 error = merged.T_a_b * T_moved_b;
  std::printf("merged: %zu of %zu views localized, %zu agree; error %.3f m, %.3f deg; %zu points added to %zu\n", merged.localized, merged.views,
              merged.agreeing, error.translation().norm(), error.rotation().angle() * 180.0 / std::numbers::pi, merged.points_from_b, a.points->points.size());
  EXPECT_LT(error.translation().norm(), 0.1);
  EXPECT_LT(error.rotation().angle(), 0.5 * std::numbers::pi / 180.0);
  EXPECT_GE(merged.agreeing, 2U);
  EXPECT_EQ(merged.merged.points->points.size(), a.points->points.size() + merged.points_from_b);
  EXPECT_LT(merged.points_from_b, b.points->points.size() / 2) << "the same place: most of B's voxels are A's";
  EXPECT_EQ(merged.dropped_layers, (std::vector<std::string>{"occupancy", "lidar_keyframes"}));

  // A room with pillars on a grid, walls 2.5 m high: no place of the warehouse.
  msgs::FusionMap other;
  other.map_id = "elsewhere";
  other.points.emplace();
  other.points->voxel_size = 0.2;
  std::mt19937 random(7);
  std::uniform_real_distribution<float> noise(-0.02F, 0.02F);
  for (float x = -15.0F; x <= 15.0F; x += 0.2F) {
    for (float y = -15.0F; y <= 15.0F; y += 0.2F) {
      other.points->points.emplace_back(x, y, noise(random));  // floor
      const bool wall = std::abs(x) > 14.9F || std::abs(y) > 14.9F;
      const bool pillar = std::hypot(std::fmod(x + 15.0F, 6.0F) - 3.0F, std::fmod(y + 15.0F, 4.5F) - 2.25F) < 0.3F;
      if (wall || pillar) {
        for (float z = 0.2F; z <= 2.5F; z += 0.2F) other.points->points.emplace_back(x, y, z + noise(random));
      }
    }
  }
  const Result<MapMergeResult> refused = merge_maps(a, other, config);
  if (refused) {
    std::printf("another place joined: %zu of %zu localized, %zu agree, at %.2f %.2f yaw %.1f\n", refused->localized, refused->views, refused->agreeing,
                refused->T_a_b.translation().x(), refused->T_a_b.translation().y(), refused->T_a_b.rotation().angle() * 180 / std::numbers::pi);
  }
  ASSERT_FALSE(refused);
  std::printf("another place: %s\n", refused.error().message.c_str());
  EXPECT_TRUE(refused.error().message.find("no view of B") != std::string::npos || refused.error().message.find("disagree") != std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
