#include "hanzo/fusion/maps/occupancy_grid.hpp"

#include <cmath>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::maps {
namespace {

using ::testing::HasSubstr;

OccupancyConfig config_with_resolution(double resolution) {
  OccupancyConfig config;
  config.resolution = resolution;
  return config;
}

/// End points on the wall x = wall_x (just inside its first cell), y from -1 to 1 m.
std::vector<Eigen::Vector2d> wall_scan(double wall_x) {
  std::vector<Eigen::Vector2d> points;
  for (double y = -1.0; y <= 1.0; y += 0.01) points.emplace_back(wall_x + 1e-3, y);
  return points;
}

TEST(OccupancyGrid, WallBecomesOccupiedAndTheCellsBeforeItFree) {
  OccupancyGrid2D grid(config_with_resolution(0.05));
  const Eigen::Vector2d origin(0.01, 0.01);
  const auto scan = wall_scan(3.0);
  for (int i = 0; i < 15; ++i) ASSERT_TRUE(grid.insert_scan(origin, scan));  // 12 misses make a cell free

  // The wall cells, x index 60, are occupied over the scanned span.
  for (int y = -19; y <= 19; ++y) EXPECT_EQ(grid.state(Eigen::Vector2i(60, y)), CellState::kOccupied) << y;
  // Every cell between the sensor and the wall along the x axis is free.
  for (int x = 0; x < 60; ++x) EXPECT_EQ(grid.state(Eigen::Vector2i(x, 0)), CellState::kFree) << x;
  // Behind the wall and beside the sensor's field: never observed.
  EXPECT_EQ(grid.state(Eigen::Vector2i(61, 0)), CellState::kUnknown);
  EXPECT_EQ(grid.state(Eigen::Vector2d(-1.0, 0.0)), CellState::kUnknown);
  EXPECT_DOUBLE_EQ(grid.probability(Eigen::Vector2i(70, 0)), 0.5);
  // The clamped maximum: 0.97.
  EXPECT_NEAR(grid.probability(Eigen::Vector2i(60, 0)), 0.97, 1e-6);
  const auto bounds = grid.observed_bounds();
  ASSERT_TRUE(bounds.has_value());
  EXPECT_EQ(bounds->second.x(), 60);
}

TEST(OccupancyGrid, EachCellIsUpdatedOncePerScanAndHitsWin) {
  OccupancyConfig config = config_with_resolution(0.1);
  OccupancyGrid2D grid(config);
  // 200 rays all crossing the cells near the origin, and one ray ending in cell (3, 0) while
  // another passes through it.
  std::vector<Eigen::Vector2d> scan = wall_scan(2.0);
  scan.emplace_back(0.35, 0.05);
  scan.emplace_back(0.95, 0.05);
  ASSERT_TRUE(grid.insert_scan(Eigen::Vector2d(0.05, 0.05), scan));
  EXPECT_NEAR(grid.probability(Eigen::Vector2i(0, 0)), config.probability_miss, 1e-6);
  EXPECT_NEAR(grid.probability(Eigen::Vector2i(1, 0)), config.probability_miss, 1e-6);
  EXPECT_NEAR(grid.probability(Eigen::Vector2i(3, 0)), config.probability_hit, 1e-6);
  EXPECT_EQ(grid.scan_count(), 1u);
}

TEST(OccupancyGrid, ReturnsBeyondMaxRangeOnlyClearSpace) {
  OccupancyConfig config = config_with_resolution(0.1);
  config.max_range = 2.0;
  OccupancyGrid2D grid(config);
  const std::vector<Eigen::Vector2d> scan{{5.05, 0.05}};
  ASSERT_TRUE(grid.insert_scan(Eigen::Vector2d(0.05, 0.05), scan));
  EXPECT_EQ(grid.observed(Eigen::Vector2i(50, 0)), false);  // the end point: too far to trust
  EXPECT_LT(grid.probability(Eigen::Vector2i(19, 0)), 0.5);  // free up to 2 m
  EXPECT_LT(grid.probability(Eigen::Vector2i(20, 0)), 0.5);  // the cut ray's last cell
  EXPECT_FALSE(grid.observed(Eigen::Vector2i(21, 0)));
}

TEST(OccupancyGrid, DiagonalRaysVisitAConnectedPathInNegativeCoordinates) {
  OccupancyGrid2D grid(config_with_resolution(0.1));
  const Eigen::Vector2d origin(-10.05, -20.05);
  const Eigen::Vector2d end(-13.03, -23.07);  // no exact corner crossings
  ASSERT_TRUE(grid.insert_scan(origin, std::vector<Eigen::Vector2d>{end}));
  EXPECT_EQ(grid.state(end), CellState::kOccupied);  // one hit: 0.85 > 0.65
  EXPECT_NEAR(grid.probability(end), 0.85, 1e-6);
  // 30 steps in x and 30 in y from the origin's cell: 60 free cells, no gaps.
  EXPECT_EQ(grid.observed_cell_count(), 61u);
  for (double t = 0.02; t < 0.98; t += 0.01) {
    const Eigen::Vector2d on_ray = origin + t * (end - origin);
    EXPECT_LT(grid.probability(on_ray), 0.5) << t;
  }
}

TEST(OccupancyGrid, ThreeDimensionalFloorScan) {
  OccupancyGrid3D grid(config_with_resolution(0.1));
  const Eigen::Vector3d sensor(0.05, 0.05, 1.05);
  std::vector<Eigen::Vector3d> floor;
  for (double x = -2.0; x <= 2.0; x += 0.05) {
    for (double y = -2.0; y <= 2.0; y += 0.05) floor.emplace_back(x, y, 0.001);  // just above z = 0
  }
  for (int i = 0; i < 15; ++i) ASSERT_TRUE(grid.insert_scan(sensor, floor));
  EXPECT_EQ(grid.state(Eigen::Vector3d(1.0, -1.0, 0.05)), CellState::kOccupied);
  EXPECT_EQ(grid.state(Eigen::Vector3d(0.05, 0.05, 0.55)), CellState::kFree);
  EXPECT_EQ(grid.state(Eigen::Vector3d(0.05, 0.05, -0.05)), CellState::kUnknown);  // below the floor
  const auto bounds = grid.observed_bounds();
  ASSERT_TRUE(bounds.has_value());
  EXPECT_EQ(bounds->first.z(), 0);
  EXPECT_EQ(bounds->second.z(), 10);
}

TEST(OccupancyGrid, BadPointsAreRejectedAndChangeNothing) {
  OccupancyGrid2D grid(config_with_resolution(0.05));
  ASSERT_TRUE(grid.insert_scan(Eigen::Vector2d::Zero(), wall_scan(1.0)));
  const std::size_t before = grid.observed_cell_count();
  std::vector<Eigen::Vector2d> bad = wall_scan(2.0);
  bad[7].x() = std::nan("");
  const Status status = grid.insert_scan(Eigen::Vector2d::Zero(), bad);
  ASSERT_FALSE(status);
  EXPECT_THAT(status.error().message, HasSubstr("end point 7"));
  EXPECT_EQ(status.error().field, "end_points[7]");
  EXPECT_FALSE(grid.insert_scan(Eigen::Vector2d(1e9, 0.0), wall_scan(1.0)));
  EXPECT_EQ(grid.observed_cell_count(), before);
  EXPECT_EQ(grid.scan_count(), 1u);
}

TEST(OccupancyGrid, ConfigValidationNamesTheValue) {
  OccupancyConfig config;
  config.probability_hit = 0.4;
  EXPECT_THAT(config.validate().error().message, HasSubstr("probability_hit"));
  config = {};
  config.resolution = -1.0;
  EXPECT_EQ(OccupancyGrid2D::create(config).error().field, "resolution");
  config = {};
  config.free_threshold = 0.8;
  EXPECT_FALSE(config.validate());
}

TEST(OccupancyGrid, LayerRoundTripKeepsEveryCell) {
  OccupancyGrid2D grid(config_with_resolution(0.05));
  ASSERT_TRUE(grid.insert_scan(Eigen::Vector2d(-0.5, 0.3), wall_scan(2.0)));
  ASSERT_TRUE(grid.insert_scan(Eigen::Vector2d(-0.5, 0.3), wall_scan(2.0)));
  const msgs::OccupancyGridLayer layer = grid.to_layer();
  EXPECT_EQ(layer.size_z, 1u);
  EXPECT_EQ(layer.occupancy.size(), std::size_t{layer.size_x} * layer.size_y);
  auto restored = OccupancyGrid2D::from_layer(layer, OccupancyConfig{});
  ASSERT_TRUE(restored.ok()) << restored.error().message;
  EXPECT_EQ(restored->config().resolution, 0.05);
  EXPECT_EQ(restored->observed_cell_count(), grid.observed_cell_count());
  grid.for_each_observed([&](const Eigen::Vector2i& cell, float) {
    EXPECT_NEAR(restored->probability(cell), grid.probability(cell), 1e-6);
    EXPECT_EQ(restored->state(cell), grid.state(cell));
  });
  // A restored grid keeps learning.
  ASSERT_TRUE(restored->insert_scan(Eigen::Vector2d(-0.5, 0.3), wall_scan(2.0)));
  EXPECT_EQ(restored->state(Eigen::Vector2d(2.001, 0.0)), CellState::kOccupied);
}

TEST(OccupancyGrid, ThreeDimensionalLayerRoundTrip) {
  OccupancyGrid3D grid(config_with_resolution(0.2));
  std::vector<Eigen::Vector3d> points;
  for (double y = -1.0; y <= 1.0; y += 0.1) points.emplace_back(3.0, y, -0.5);
  ASSERT_TRUE(grid.insert_scan(Eigen::Vector3d(0.1, 0.1, 1.1), points));
  const msgs::OccupancyGridLayer layer = grid.to_layer();
  EXPECT_GT(layer.size_z, 1u);
  auto restored = OccupancyGrid3D::from_layer(layer, OccupancyConfig{});
  ASSERT_TRUE(restored.ok()) << restored.error().message;
  EXPECT_EQ(restored->observed_cell_count(), grid.observed_cell_count());
  grid.for_each_observed([&](const Eigen::Vector3i& cell, float) {
    EXPECT_NEAR(restored->probability(cell), grid.probability(cell), 1e-6);
  });
}

TEST(OccupancyGrid, LayersThatDoNotFitAreRejected) {
  msgs::OccupancyGridLayer layer;
  layer.resolution = 0.1;
  layer.size_x = 2;
  layer.size_y = 2;
  layer.size_z = 2;
  layer.occupancy.assign(8, 0.9f);
  EXPECT_THAT(OccupancyGrid2D::from_layer(layer, {}).error().message, HasSubstr("size_z"));
  layer.size_z = 1;
  layer.occupancy.assign(3, 0.9f);  // not size_x * size_y
  EXPECT_FALSE(OccupancyGrid2D::from_layer(layer, {}).ok());
  layer.occupancy.assign(4, 0.9f);
  layer.origin.position = {0.05, 0.0, 0.0};  // half a cell off the world grid
  EXPECT_THAT(OccupancyGrid2D::from_layer(layer, {}).error().message, HasSubstr("whole number of cells"));
  layer.origin.position = {0.1, 0.0, 0.0};
  layer.origin.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()));
  EXPECT_THAT(OccupancyGrid2D::from_layer(layer, {}).error().message, HasSubstr("rotated"));
}

}  // namespace
}  // namespace hanzo::fusion::maps
