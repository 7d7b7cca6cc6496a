// Traversable cells of a synthetic course sampled every 3 cm with 1 cm of noise: flat floor, a
// 15 cm kerb platform, a 10 degree ramp up and down, a 30 degree ramp up and down and a box.
// Each cell's label against the course's own geometry (normals estimated from the points as
// the map builder does); no row crosses the kerb's edges through traversable cells, the steep
// ramp and the box are not traversable, the gentle ramp and the kerb's top are; free cells no
// point shows keep the occupancy's verdict.

#include "hanzo/fusion/maps/traversability.hpp"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/maps/geometric_labels.hpp"

namespace hanzo::fusion::maps {
namespace {

using msgs::SemanticLabel;

const double kGentle = std::tan(10.0 * M_PI / 180.0);
const double kSteep = std::tan(30.0 * M_PI / 180.0);

// The course's ground height at x (floor 0).
double course_height(double x) {
  if (x >= 2.0 && x <= 4.0) return 0.15;                         // kerb platform
  if (x >= 5.0 && x <= 7.0) return kGentle * (x - 5.0);          // 10 degrees up
  if (x > 7.0 && x <= 9.0) return kGentle * (9.0 - x);           // and down
  if (x >= 9.5 && x <= 10.5) return kSteep * (x - 9.5);          // 30 degrees up
  if (x > 10.5 && x <= 11.5) return kSteep * (11.5 - x);         // and down
  return 0.0;
}
bool in_box(double x, double y) { return x >= 0.5 && x <= 1.0 && y >= 1.0 && y <= 1.5; }
constexpr double kBoxHeight = 0.6;

TEST(Traversability, KerbEdgesSteepRampsAndBoxesAreNotTraversableGentleRampsAre) {
  std::mt19937 random(5);
  std::normal_distribution<float> noise(0.0F, 0.01F);
  msgs::PointLayer layer;
  const auto add = [&](double x, double y, double z) {
    layer.points.emplace_back(static_cast<float>(x) + noise(random), static_cast<float>(y) + noise(random), static_cast<float>(z) + noise(random));
  };
  constexpr double kStep = 0.03;
  for (double x = 0.0; x <= 12.0; x += kStep) {
    for (double y = 0.0; y <= 3.0; y += kStep) {
      if (in_box(x, y)) {
        add(x, y, kBoxHeight);  // the box's top; the floor beneath is not seen
      } else {
        add(x, y, course_height(x));
      }
    }
    for (double y = 0.0; y <= 3.0; y += kStep) {  // the kerb's faces
      for (double z = 0.0; z < 0.15; z += kStep) {
        if (std::abs(x - 2.0) < kStep / 2 || std::abs(x - 4.0) < kStep / 2) add(x, y, z);
      }
    }
  }
  for (double t = 0.0; t <= 0.5; t += kStep) {  // the box's faces
    for (double z = 0.0; z < kBoxHeight; z += kStep) {
      add(0.5 + t, 1.0, z);
      add(0.5 + t, 1.5, z);
      add(0.5, 1.0 + t, z);
      add(1.0, 1.0 + t, z);
    }
  }
  std::vector<Eigen::Vector3f> normals;
  ASSERT_TRUE(label_points(layer, {}, &normals).ok());

  msgs::OccupancyGridLayer grid;
  grid.resolution = 0.1;
  grid.size_x = 130;  // to x = 13 m: the last metre has no points
  grid.size_y = 30;
  grid.origin.position = Eigen::Vector3d(0.0, 0.0, 0.0);
  grid.occupancy.assign(static_cast<std::size_t>(grid.size_x) * grid.size_y, 0.3F);  // all free: only the ground decides
  const TraversabilityConfig config;
  label_grid(grid, layer, normals, 0.65, 0.35, config);
  ASSERT_EQ(grid.labels.size(), grid.occupancy.size());

  // Cells within a cell of where the course changes are ambiguous and left out of the count.
  const auto near = [](double value, std::initializer_list<double> edges) {
    for (double edge : edges) {
      if (std::abs(value - edge) < 0.15) return true;
    }
    return false;
  };
  std::size_t counted = 0, correct = 0, kerb_edges = 0, kerb_edges_blocked = 0, steep = 0, steep_blocked = 0, gentle = 0, gentle_open = 0;
  for (uint32_t cy = 0; cy < grid.size_y; ++cy) {
    for (uint32_t cx = 0; cx < grid.size_x; ++cx) {
      const double x = (cx + 0.5) * grid.resolution, y = (cy + 0.5) * grid.resolution;
      const SemanticLabel label = grid.labels[static_cast<std::size_t>(cy) * grid.size_x + cx];
      if (x > 12.1) {
        EXPECT_EQ(label, SemanticLabel::kTraversable) << "no point shows the ground at x = " << x << ": the free cell stays free";
        continue;
      }
      if (y > 2.9) continue;  // the course's last row of cells is half sampled
      const bool traversable = label == SemanticLabel::kTraversable;
      if (std::abs(x - 1.95) < 0.01 || std::abs(x - 3.95) < 0.01) {  // the cells either side of the kerb's edges
        ++kerb_edges;
        kerb_edges_blocked += !traversable || grid.labels[static_cast<std::size_t>(cy) * grid.size_x + cx + 1] != SemanticLabel::kTraversable;
      }
      if (x > 9.65 && x < 11.35 && !near(x, {10.5})) {
        ++steep;
        steep_blocked += !traversable;
      }
      if (x > 5.15 && x < 8.85) {
        ++gentle;
        gentle_open += traversable;
      }
      if (near(x, {0.5, 1.0, 2.0, 4.0, 5.0, 7.0, 9.0, 9.5, 10.5, 11.5}) && y > 0.85 && y < 1.65) continue;
      if (near(x, {2.0, 4.0, 5.0, 7.0, 9.0, 9.5, 10.5, 11.5})) continue;
      const bool truth = !in_box(x, y) && !(x > 9.5 && x < 11.5) && !(near(y, {1.0, 1.5}) && x > 0.4 && x < 1.1);
      ++counted;
      correct += traversable == truth;
    }
  }
  std::printf("course: %zu of %zu cells right; kerb edges %zu of %zu blocked; steep ramp %zu of %zu; gentle ramp %zu of %zu open\n", correct,
              counted, kerb_edges_blocked, kerb_edges, steep_blocked, steep, gentle_open, gentle);
  EXPECT_GT(static_cast<double>(correct), 0.98 * static_cast<double>(counted));
  EXPECT_EQ(kerb_edges_blocked, kerb_edges) << "every row: the kerb's edge is a step (one of the cells either side not traversable)";
  EXPECT_GT(static_cast<double>(steep_blocked), 0.95 * static_cast<double>(steep)) << "30 degrees is too steep";
  EXPECT_GT(static_cast<double>(gentle_open), 0.98 * static_cast<double>(gentle)) << "10 degrees is drivable";
}

TEST(Traversability, GroundCellsMeasureSlopeAndStep) {
  // A plane rising 20 % along x, sampled densely without noise: every inner cell's slope is
  // atan(0.2), its step one cell's rise (diagonal neighbours: the same).
  std::vector<Eigen::Vector3f> points, normals;
  for (double x = 0.0; x < 2.0; x += 0.02) {
    for (double y = 0.0; y < 2.0; y += 0.02) {
      points.emplace_back(static_cast<float>(x), static_cast<float>(y), static_cast<float>(0.2 * x));
      normals.push_back(Eigen::Vector3f(-0.2F, 0.0F, 1.0F).normalized());
    }
  }
  msgs::OccupancyGridLayer grid;
  grid.resolution = 0.2;
  grid.size_x = grid.size_y = 10;
  const std::vector<GroundCell> cells = ground_cells(grid, points, normals, {});
  ASSERT_EQ(cells.size(), 100u);
  const GroundCell& inner = cells[5 * 10 + 5];
  ASSERT_TRUE(inner.has_ground());
  EXPECT_NEAR(inner.height, 0.2 * 1.1, 0.01);  // the cell's middle
  EXPECT_NEAR(inner.slope_deg, std::atan(0.2) * 180.0 / M_PI, 0.5);
  EXPECT_NEAR(inner.step_m, 0.2 * 0.2, 0.01);
  EXPECT_FALSE(inner.blocked);

  TraversabilityConfig bad;
  bad.max_step_m = 0.0;
  EXPECT_NE(bad.validate().error().message.find("max_step_m"), std::string::npos);
  GeometricLabelConfig labels;
  labels.traversability.max_slope_deg = 95.0;
  EXPECT_NE(labels.validate().error().message.find("traversability.max_slope_deg"), std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion::maps
