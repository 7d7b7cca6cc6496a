// The Session's map labelled against the simulator's truth: every point of the warehouse
// robot's LiDAR map, moved into the simulator's world by the yaw and translation that align the
// session's optimized trajectory with the truth, is matched to the nearest surface of the
// simulated world (the ground, a box face, a cylinder), whose exact normal and the world's floor
// height give its true label by the same rules (maps/geometric_labels.hpp).

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <utility>
#include <vector>
#include <string>
#include <variant>

#include <gtest/gtest.h>

#include "hanzo/fusion/eval/alignment.hpp"
#include "hanzo/fusion/maps/geometric_labels.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "scenario_replay.hpp"
#include "simulated_surfaces.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using testing::nearest_surface;
using testing::NearestSurface;

// Horizontal distance (m) from (x, y) to the nearest footprint edge of a box or cylinder, and
// whether it lies inside one.
std::pair<double, bool> nearest_footprint_edge(const sim::WorldDescription& world, const Eigen::Vector2d& xy) {
  double nearest = std::numeric_limits<double>::infinity();
  bool inside = false;
  for (const sim::Box& box : world.boxes) {
    const Eigen::Rotation2Dd yaw(box.yaw);
    const Eigen::Vector2d local = yaw.inverse() * (xy - box.center.head<2>());
    const Eigen::Vector2d half = box.half_size.head<2>();
    const Eigen::Vector2d outside = (local.cwiseAbs() - half).cwiseMax(0.0);
    const bool in = outside.isZero();
    inside = inside || in;
    nearest = std::min(nearest, in ? (half - local.cwiseAbs()).minCoeff() : outside.norm());
  }
  for (const sim::Cylinder& cylinder : world.cylinders) {
    const double radial = (xy - cylinder.base_center.head<2>()).norm();
    inside = inside || radial <= cylinder.radius;
    nearest = std::min(nearest, std::abs(radial - cylinder.radius));
  }
  return {nearest, inside};
}

TEST(MapLabels, TheWarehouseMapsPointsAreLabelledAsTheSimulatedWorld) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/warehouse_robot.yaml").value();
  scenario.duration = 20.0;
  scenario.num_threads = 0;
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  auto session = Session::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario)).value();
  (void)testing::replay(*simulation, *session);
  testing::ReplayedTrajectories optimized = testing::optimized_with_truth(*session, *simulation);
  const eval::SimilarityTransform T_sim_session = eval::align_trajectory(optimized.estimate, optimized.truth, eval::Alignment::kYaw).value();
  const msgs::FusionMap map = session->map();
  ASSERT_TRUE(map.points);
  ASSERT_EQ(map.points->labels.size(), map.points->points.size());
  ASSERT_GT(map.points->points.size(), 1000u);
  const sim::WorldDescription& world = simulation->world().description();
  const maps::GeometricLabelConfig config;
  std::size_t right = 0, compared = 0;
  std::array<std::size_t, 5> truth_counts{}, right_counts{};
  for (std::size_t i = 0; i < map.points->points.size(); ++i) {
    const Eigen::Vector3d point = T_sim_session.rotation * map.points->points[i].cast<double>() + T_sim_session.translation;
    const NearestSurface surface = nearest_surface(world, point);
    if (surface.distance > 0.2) continue;  // a moving box's point, or one the map misplaced
    const msgs::SemanticLabel truth = maps::geometric_label(surface.normal.cast<float>(), point.z(), world.ground_height, config);
    ++compared;
    ++truth_counts[static_cast<std::size_t>(truth)];
    if (map.points->labels[i] == truth) {
      ++right;
      ++right_counts[static_cast<std::size_t>(truth)];
    }
  }
  const double accuracy = static_cast<double>(right) / static_cast<double>(compared);
  std::printf("warehouse map: %zu points, %zu on a known surface, %.1f %% labelled as the truth (floor %zu/%zu, wall %zu/%zu, obstacle %zu/%zu, unknown %zu/%zu)\n",
              map.points->points.size(), compared, 100.0 * accuracy, right_counts[1], truth_counts[1], right_counts[2], truth_counts[2], right_counts[3],
              truth_counts[3], right_counts[0], truth_counts[0]);
  EXPECT_GT(static_cast<double>(compared), 0.9 * static_cast<double>(map.points->points.size()));
  EXPECT_GT(truth_counts[static_cast<std::size_t>(msgs::SemanticLabel::kFloor)], 100u);
  EXPECT_GT(truth_counts[static_cast<std::size_t>(msgs::SemanticLabel::kWall)], 100u);
  EXPECT_GT(accuracy, 0.95);

  // The 2D grid: traversable cells lie outside every box and pillar, wall and obstacle cells on
  // one's edge (within 1.5 cells: the map's own error and the cell's extent).
  ASSERT_TRUE(map.occupancy);
  const msgs::OccupancyGridLayer& grid = *map.occupancy;
  ASSERT_EQ(grid.labels.size(), grid.occupancy.size());
  const SE3 T_world_grid = grid.origin.to_se3();
  std::size_t traversable = 0, traversable_outside = 0, occupied = 0, occupied_on_edge = 0;
  for (uint32_t y = 0; y < grid.size_y; ++y) {
    for (uint32_t x = 0; x < grid.size_x; ++x) {
      const msgs::SemanticLabel label = grid.labels[static_cast<std::size_t>(y) * grid.size_x + x];
      if (label == msgs::SemanticLabel::kUnknown || label == msgs::SemanticLabel::kFloor) continue;
      const Eigen::Vector3d centre_session = T_world_grid * Eigen::Vector3d((x + 0.5) * grid.resolution, (y + 0.5) * grid.resolution, 0.0);
      const Eigen::Vector3d centre = T_sim_session.rotation * centre_session + T_sim_session.translation;
      const auto [edge_distance, inside] = nearest_footprint_edge(world, centre.head<2>());
      if (label == msgs::SemanticLabel::kTraversable) {
        ++traversable;
        traversable_outside += !inside || edge_distance < grid.resolution;
      } else {
        ++occupied;
        occupied_on_edge += edge_distance <= 1.5 * grid.resolution;
      }
    }
  }
  std::printf("warehouse grid (%.2f m cells): %zu traversable, %.1f %% outside the boxes; %zu wall or obstacle, %.1f %% on a box's edge\n",
              grid.resolution, traversable, 100.0 * traversable_outside / static_cast<double>(traversable), occupied,
              100.0 * occupied_on_edge / static_cast<double>(occupied));
  EXPECT_GT(traversable, 1000u);
  EXPECT_GT(occupied, 100u);
  EXPECT_GT(static_cast<double>(traversable_outside), 0.97 * static_cast<double>(traversable));
  EXPECT_GT(static_cast<double>(occupied_on_edge), 0.95 * static_cast<double>(occupied));
}

// The first 20 s of examples/scenarios/warehouse_segmented.yaml: the warehouse robot with a
// segmenter on its front camera (5 % of the pixels given a wrong class) and two people walking
// through the camera's and the LiDAR's view.
struct SegmentedWarehouse {
  std::unique_ptr<sim::ScenarioSimulation> simulation;
  std::unique_ptr<Session> session;
  eval::SimilarityTransform T_sim_session;
  msgs::FusionMap map;
};

SegmentedWarehouse map_segmented_warehouse(std::vector<std::string> dynamic_classes, bool remove_moving_points) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/warehouse_segmented.yaml").value();
  scenario.duration = 20.0;
  scenario.num_threads = 0;
  SegmentedWarehouse out;
  out.simulation = sim::ScenarioSimulation::create(scenario).value();
  config::FusionConfig config = sim::scenario_fusion_config(scenario);
  config.vision.dynamic_objects.classes = std::move(dynamic_classes);
  config.mapping.remove_moving_points = remove_moving_points;
  out.session = Session::create(config, sim::scenario_calibration(scenario)).value();
  (void)testing::replay(*out.simulation, *out.session);
  testing::ReplayedTrajectories optimized = testing::optimized_with_truth(*out.session, *out.simulation);
  out.T_sim_session = eval::align_trajectory(optimized.estimate, optimized.truth, eval::Alignment::kYaw).value();
  out.map = out.session->map();
  return out;
}

// Map points more than 0.2 m from every static surface of the simulated world: on the people.
std::size_t points_off_the_static_world(const SegmentedWarehouse& run) {
  std::size_t off = 0;
  for (const Eigen::Vector3f& stored : run.map.points->points) {
    const Eigen::Vector3d point = run.T_sim_session.rotation * stored.cast<double>() + run.T_sim_session.translation;
    off += nearest_surface(run.simulation->world().description(), point).distance > 0.2;
  }
  return off;
}

// Every map voxel a segmentation reached carries the fused class of the simulated surface it
// lies on (target: >= 97 % at 5 % pixel noise), the grid's cells take their points' classes, and
// the people are left out of the map.
TEST(MapLabels, ProjectedSegmentationClassesLabelTheWarehouseMapsVoxels) {
  const SegmentedWarehouse run = map_segmented_warehouse(config::DynamicObjectsConfig{}.classes, true);
  const msgs::FusionMap& map = run.map;
  ASSERT_TRUE(map.points);
  const msgs::PointLayer& points = *map.points;
  ASSERT_EQ(points.classes.size(), points.points.size());
  ASSERT_EQ(points.class_probability.size(), points.points.size());
  const sim::WorldDescription& world = run.simulation->world().description();
  std::size_t classified = 0, compared = 0, right = 0;
  double probability_sum = 0.0;
  for (std::size_t i = 0; i < points.points.size(); ++i) {
    if (points.classes[i] == msgs::kNoClass) continue;
    ++classified;
    ASSERT_LT(points.classes[i], map.semantic_classes.size());
    probability_sum += points.class_probability[i];
    const Eigen::Vector3d point = run.T_sim_session.rotation * points.points[i].cast<double>() + run.T_sim_session.translation;
    const NearestSurface surface = nearest_surface(world, point);
    if (surface.distance > 0.2) continue;  // a point the map misplaced (or a person's)
    ++compared;
    right += map.semantic_classes[points.classes[i]] == surface.class_name;
  }
  const MappingSummary summary = run.session->mapping_summary();
  const double accuracy = static_cast<double>(right) / static_cast<double>(compared);
  const std::size_t on_people = points_off_the_static_world(run);
  std::printf("warehouse map: %zu points, %zu classified (%zu classes), %zu on a known surface, %.2f %% of their classes right; "
              "%llu LiDAR points labelled, %llu on people left out; %zu map points off the static world\n",
              points.points.size(), classified, map.semantic_classes.size(), compared, 100.0 * accuracy,
              static_cast<unsigned long long>(summary.lidar_points_labelled), static_cast<unsigned long long>(summary.lidar_points_masked), on_people);
  EXPECT_GT(classified, points.points.size() / 5);
  EXPECT_GT(static_cast<double>(compared), 0.95 * static_cast<double>(classified));
  EXPECT_GE(accuracy, 0.97);
  EXPECT_GT(probability_sum / static_cast<double>(classified), 0.9);
  ASSERT_TRUE(map.occupancy);
  ASSERT_EQ(map.occupancy->classes.size(), map.occupancy->occupancy.size());
  EXPECT_GT(std::count_if(map.occupancy->classes.begin(), map.occupancy->classes.end(), [](uint16_t c) { return c != msgs::kNoClass; }), 1000);

  // The same run without moving classes and without free-space removal keeps the people's
  // points in the map.
  const SegmentedWarehouse unmasked = map_segmented_warehouse({}, false);
  const std::size_t on_people_unmasked = points_off_the_static_world(unmasked);
  std::printf("map points off the static world: %zu masked, %zu unmasked\n", on_people, on_people_unmasked);
  EXPECT_GT(summary.lidar_points_masked, 1000u);
  EXPECT_EQ(unmasked.session->mapping_summary().lidar_points_masked, 0u);
  EXPECT_LT(static_cast<double>(on_people), 0.45 * static_cast<double>(on_people_unmasked));
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
