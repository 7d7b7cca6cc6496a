// The Session's map labelled against the simulator's truth: every point of the warehouse
// robot's LiDAR map, moved into the simulator's world by the yaw and translation that align the
// session's optimized trajectory with the truth, is matched to the nearest surface of the
// simulated world (the ground, a box face, a cylinder), whose exact normal and the world's floor
// height give its true label by the same rules (maps/geometric_labels.hpp).

#include <algorithm>
#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "hanzo/fusion/eval/alignment.hpp"
#include "hanzo/fusion/maps/geometric_labels.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "scenario_replay.hpp"

namespace hanzo::fusion::pipeline {
namespace {

struct NearestSurface {
  double distance = std::numeric_limits<double>::infinity();
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
};

void offer(NearestSurface& nearest, double distance, const Eigen::Vector3d& normal) {
  if (distance < nearest.distance) nearest = {distance, normal};
}

// The nearest face of an upright box: distances to each face's rectangle, in the box's frame.
void nearest_box_face(const sim::Box& box, const Eigen::Vector3d& point, NearestSurface& nearest) {
  const Eigen::Matrix3d R = Eigen::AngleAxisd(box.yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d local = R.transpose() * (point - box.center);
  for (int axis = 0; axis < 3; ++axis) {
    for (const double side : {-1.0, 1.0}) {
      Eigen::Vector3d on_face = local.cwiseMax(-box.half_size).cwiseMin(box.half_size);
      on_face(axis) = side * box.half_size(axis);
      offer(nearest, (local - on_face).norm(), R * (side * Eigen::Vector3d::Unit(axis)));
    }
  }
}

void nearest_cylinder_surface(const sim::Cylinder& cylinder, const Eigen::Vector3d& point, NearestSurface& nearest) {
  const Eigen::Vector2d radial = (point - cylinder.base_center).head<2>();
  const double height = std::clamp(point.z() - cylinder.base_center.z(), 0.0, cylinder.height);
  const double radius = radial.norm();
  const Eigen::Vector2d direction = radius > 1e-9 ? Eigen::Vector2d(radial / radius) : Eigen::Vector2d::UnitX();
  const Eigen::Vector3d on_side(cylinder.base_center.x() + cylinder.radius * direction.x(), cylinder.base_center.y() + cylinder.radius * direction.y(),
                                cylinder.base_center.z() + height);
  offer(nearest, (point - on_side).norm(), Eigen::Vector3d(direction.x(), direction.y(), 0.0));
  const Eigen::Vector2d on_top_radial = radius > cylinder.radius ? Eigen::Vector2d(direction * cylinder.radius) : radial;
  const Eigen::Vector3d on_top(cylinder.base_center.x() + on_top_radial.x(), cylinder.base_center.y() + on_top_radial.y(),
                               cylinder.base_center.z() + cylinder.height);
  offer(nearest, (point - on_top).norm(), Eigen::Vector3d::UnitZ());
}

NearestSurface nearest_surface(const sim::WorldDescription& world, const Eigen::Vector3d& point) {
  NearestSurface nearest;
  if (world.has_ground) offer(nearest, std::abs(point.z() - world.ground_height), Eigen::Vector3d::UnitZ());
  for (const sim::Box& box : world.boxes) nearest_box_face(box, point, nearest);
  for (const sim::Cylinder& cylinder : world.cylinders) nearest_cylinder_surface(cylinder, point, nearest);
  return nearest;
}

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

}  // namespace
}  // namespace hanzo::fusion::pipeline
