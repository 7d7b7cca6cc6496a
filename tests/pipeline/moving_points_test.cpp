// Moving vehicles and people leave no trails in the LiDAR map: examples/scenarios/urban_traffic.yaml
// (a car driving 270 m through traffic: a car leading in its lane, oncoming and crossing cars,
// two pedestrians) mapped three ways from one recording: nothing removed, the free-space
// evidence alone (no detector), and the front camera's detections masking too. Each map is
// moved into the simulator's world by the alignment of its optimized trajectory with the truth;
// a trail point is a map point farther than 0.3 m from every static surface inside the region a
// mover swept. The simulator's per-point truth counts the LiDAR returns that fell on movers.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "hanzo/fusion/eval/alignment.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "scenario_replay.hpp"
#include "simulated_surfaces.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using Recording = std::vector<std::pair<std::string, msgs::SensorMessage>>;

struct MapCount {
  std::size_t points = 0;
  std::size_t static_points = 0;  // within 0.1 m of a static surface
  std::size_t trail_points = 0;   // > 0.3 m from every static surface, where a mover went
  uint64_t lidar_points_masked = 0;
};

// Horizontal distance from xy to the segment [a, b].
double distance_to_segment(const Eigen::Vector2d& xy, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const Eigen::Vector2d ab = b - a;
  const double t = std::clamp((xy - a).dot(ab) / std::max(ab.squaredNorm(), 1e-12), 0.0, 1.0);
  return (xy - (a + t * ab)).norm();
}

// Whether a world point lies where one of the world's movers went (its footprint along its path,
// up to its height, with 0.3 m around).
bool where_a_mover_went(const sim::WorldDescription& world, const Eigen::Vector3d& point) {
  for (const sim::MovingBox& mover : world.moving_boxes) {
    const double reach = mover.box.half_size.head<2>().norm() + 0.3;
    if (point.z() - world.ground_height > 2.0 * mover.box.half_size.z() + 0.3) continue;
    for (std::size_t i = 0; i + 1 < mover.path.size(); ++i) {
      if (distance_to_segment(point.head<2>(), mover.path[i], mover.path[i + 1]) <= reach) return true;
    }
  }
  return false;
}

MapCount map_traffic(const sim::Scenario& scenario, const Recording& recording, const sim::WorldDescription& world, bool remove_moving_points,
                     std::vector<std::string> dynamic_classes) {
  config::FusionConfig config = sim::scenario_fusion_config(scenario);
  config.mapping.remove_moving_points = remove_moving_points;
  config.vision.dynamic_objects.classes = std::move(dynamic_classes);
  auto session = Session::create(config, sim::scenario_calibration(scenario)).value();
  for (const auto& [sensor, message] : recording) (void)session->push(sensor, msgs::SensorMessage(message));
  session->flush();
  auto simulation = sim::ScenarioSimulation::create(scenario).value();  // the truth's trajectory
  testing::ReplayedTrajectories optimized = testing::optimized_with_truth(*session, *simulation);
  const eval::SimilarityTransform T_sim_session = eval::align_trajectory(optimized.estimate, optimized.truth, eval::Alignment::kYaw).value();
  const msgs::FusionMap map = session->map();
  MapCount count;
  const MappingSummary summary = session->mapping_summary();
  count.lidar_points_masked = summary.lidar_points_masked;
  EXPECT_EQ(summary.map_points_moving_removed > 0, remove_moving_points);
  if (!map.points) return count;
  for (const Eigen::Vector3f& stored : map.points->points) {
    const Eigen::Vector3d point = T_sim_session.rotation * stored.cast<double>() + T_sim_session.translation;
    ++count.points;
    const double distance = testing::nearest_surface(world, point).distance;
    count.static_points += distance <= 0.1;
    count.trail_points += distance > 0.3 && where_a_mover_went(world, point);
  }
  return count;
}

TEST(MovingPoints, CarsAndPeopleLeaveNoTrailsInTheCityMapWithOrWithoutDetections) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/urban_traffic.yaml").value();
  scenario.num_threads = 0;
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  // The recording, and the simulator's truth of how many LiDAR returns fell on movers.
  Recording recording;
  std::size_t observed_on_movers = 0;
  ASSERT_TRUE(simulation->run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) {
    if (std::holds_alternative<msgs::PointCloudMessage>(message)) {
      for (const int object : simulation->lidar_object_ids(sensor.name)) observed_on_movers += simulation->world().is_moving(object) ? 1 : 0;
    }
    recording.emplace_back(sensor.name, std::move(message));
    return ok_status();
  }).ok());
  const sim::WorldDescription& world = simulation->world().description();

  const MapCount unfiltered = map_traffic(scenario, recording, world, false, {});
  const MapCount geometric = map_traffic(scenario, recording, world, true, {});
  const MapCount detected = map_traffic(scenario, recording, world, true, config::DynamicObjectsConfig{}.classes);
  for (const auto& [name, count] : {std::pair{"nothing removed", unfiltered}, std::pair{"free space", geometric}, std::pair{"free space + detections", detected}}) {
    std::printf("%-24s %7zu map points, %7zu on static surfaces, %5zu trail points (%.2f %% of the unfiltered map's), %llu LiDAR points masked\n", name,
                count.points, count.static_points, count.trail_points,
                100.0 * static_cast<double>(count.trail_points) / static_cast<double>(unfiltered.trail_points),
                static_cast<unsigned long long>(count.lidar_points_masked));
  }
  std::printf("LiDAR returns on movers (the simulator's per-point truth): %zu; trail points per observed return: %.3f %% (free space), %.3f %% "
              "(free space + detections)\n",
              observed_on_movers, 100.0 * static_cast<double>(geometric.trail_points) / static_cast<double>(observed_on_movers),
              100.0 * static_cast<double>(detected.trail_points) / static_cast<double>(observed_on_movers));
  // Points on movers in the final map: under 1 % of the returns the LiDAR observed on them (the
  // issue's measure); against the unfiltered map's trails (a voxel map keeps one point of many
  // returns) 3.9 % stay (bench/RESULTS.md).
  ASSERT_GT(observed_on_movers, 50000u);
  EXPECT_LT(static_cast<double>(geometric.trail_points), 0.01 * static_cast<double>(observed_on_movers));
  EXPECT_LT(static_cast<double>(detected.trail_points), 0.01 * static_cast<double>(observed_on_movers));
  ASSERT_GT(unfiltered.trail_points, 2000u);
  EXPECT_LT(static_cast<double>(geometric.trail_points), 0.06 * static_cast<double>(unfiltered.trail_points));
  EXPECT_LE(detected.trail_points, geometric.trail_points);
  EXPECT_GT(detected.lidar_points_masked, 1000u);
  // The static world stays: at most 0.1 % of the points on static surfaces removed.
  EXPECT_GT(static_cast<double>(geometric.static_points), 0.999 * static_cast<double>(unfiltered.static_points));
  EXPECT_GT(static_cast<double>(detected.static_points), 0.999 * static_cast<double>(unfiltered.static_points));
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
