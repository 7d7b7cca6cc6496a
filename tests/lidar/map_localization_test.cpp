// Localization in a known map on simulated scans of a yard with exact poses: the map is built
// from scans along a path, the query is a scan from a pose no map scan was taken at.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>

#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/lidar/map_localization.hpp"
#include "simulated_scan.hpp"

namespace hanzo::fusion::lidar {
namespace {

using ::testing::HasSubstr;
using testing_support::registration_world;
using testing_support::scan;

SE3 sensor_pose(double x, double y, double yaw, double roll = 0.0) {
  return SE3(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), yaw) * SO3::from_axis_angle(Eigen::Vector3d::UnitX(), roll),
             Eigen::Vector3d(x, y, 1.5));
}

// The yard's map: scans from five poses, in the world frame, 0.2 m voxels (as a session's map).
std::vector<Eigen::Vector3f> yard_map(const sim::World& world) {
  cloud::PointCloud map;
  int seed = 1;
  for (const SE3& pose : {sensor_pose(-12, -8, 0.0), sensor_pose(-4, 8, 1.0), sensor_pose(6, -9, -0.5), sensor_pose(14, 6, 2.0),
                          sensor_pose(0, 0, 3.0)}) {
    const cloud::PointCloud points = cloud::transformed(scan(world, pose, 0.01, static_cast<uint32_t>(seed++)), pose);
    map.positions.insert(map.positions.end(), points.positions.begin(), points.positions.end());
  }
  return cloud::voxel_downsample(map, 0.2).positions;
}

LidarOdometryConfig indoor_odometry() {
  LidarOdometryConfig odometry;
  odometry.map.voxel_size = 0.5;
  odometry.source_voxel_size = 0.25;
  return odometry;
}

void expect_near_pose(const SE3& actual, const SE3& expected, double meters, double radians) {
  EXPECT_LT((actual.translation() - expected.translation()).norm(), meters)
      << actual.translation().transpose() << " vs " << expected.translation().transpose();
  EXPECT_LT((expected.rotation().inverse() * actual.rotation()).log().norm(), radians);
}

class MapLocalization : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    world_ = new sim::World(registration_world());
    auto localizer = MapLocalizer::create(yard_map(*world_), {}, indoor_odometry());
    ASSERT_TRUE(localizer.ok()) << localizer.error().message;
    localizer_ = new MapLocalizer(std::move(localizer).value());
  }
  static void TearDownTestSuite() {
    delete localizer_;
    delete world_;
  }
  static sim::World* world_;
  static MapLocalizer* localizer_;
};
sim::World* MapLocalization::world_ = nullptr;
MapLocalizer* MapLocalization::localizer_ = nullptr;

TEST_F(MapLocalization, FindsAScanAnywhereInTheMapWithoutAGuess) {
  // Tilted 3 degrees; the orientation handed in has the right roll but a wrong heading.
  const SE3 truth = sensor_pose(4.5, 3.2, -2.3, 0.05);
  const cloud::PointCloud query = scan(*world_, truth, 0.01, 99);
  const SO3 wrong_heading = SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 1.0) * truth.rotation();
  auto found = localizer_->localize(query.positions, wrong_heading);
  ASSERT_TRUE(found.ok()) << found.error().message;
  expect_near_pose(found->T_map_sensor, truth, 0.05, 0.01);
  EXPECT_TRUE(found->global);
  EXPECT_GT(found->score, 0.4);
  EXPECT_LT(found->inlier_rmse, 0.05);
  EXPECT_LT(found->seen_through_fraction, 0.15);
  EXPECT_GT(found->headings, 300u);
  // Branch and bound scores a small part of the headings x cells an exhaustive search would.
  EXPECT_LT(found->nodes_evaluated, found->headings * 100u);
}

TEST_F(MapLocalization, SearchesLargeAreasOnACoarserGridAndStillRefinesToCentimetres) {
  MapLocalizerConfig coarse;
  coarse.search_cells = 1000;  // the yard (about 40 x 30 m) at 0.5 m cells instead of 0.2 m
  auto localizer = MapLocalizer::create(yard_map(*world_), coarse, indoor_odometry());
  ASSERT_TRUE(localizer.ok()) << localizer.error().message;
  const SE3 truth = sensor_pose(4.5, 3.2, -2.3);
  auto found = localizer->localize(scan(*world_, truth, 0.01, 11).positions, truth.rotation());
  ASSERT_TRUE(found.ok()) << found.error().message;
  expect_near_pose(found->T_map_sensor, truth, 0.05, 0.01);
}

TEST_F(MapLocalization, RefinesAGuessInsideItsWindow) {
  const SE3 truth = sensor_pose(-8.0, 2.0, 0.7);
  const cloud::PointCloud query = scan(*world_, truth, 0.01, 7);
  MapLocalizationQuery window;
  window.T_map_sensor_guess = SE3(truth.rotation() * SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 0.3),
                                  truth.translation() + Eigen::Vector3d(1.5, -1.0, 0.4));
  window.linear_window = 3.0;
  window.angular_window = 0.5;
  auto found = localizer_->localize(query.positions, truth.rotation(), window);
  ASSERT_TRUE(found.ok()) << found.error().message;
  expect_near_pose(found->T_map_sensor, truth, 0.05, 0.01);
  EXPECT_FALSE(found->global);

  // A window that excludes the true pose finds nothing that verifies.
  window.T_map_sensor_guess = SE3(truth.rotation(), truth.translation() + Eigen::Vector3d(8.0, 0.0, 0.0));
  window.linear_window = 1.0;
  window.angular_window = 0.1;
  auto wrong = localizer_->localize(query.positions, truth.rotation(), window);
  if (wrong.ok()) {  // whatever it returns must not claim a pose far from where the scan was taken
    ADD_FAILURE() << "localized at " << wrong->T_map_sensor.translation().transpose();
  }
}

TEST_F(MapLocalization, RefusesAScanOfAnotherPlace) {
  // A different yard: same walls, other boxes.
  sim::WorldDescription description;
  sim::Box wall;
  wall.center = {0, 12, 2};
  wall.half_size = {6, 0.3, 2};
  description.boxes = {wall};
  wall.center = {-7, 0, 1};
  wall.half_size = {0.3, 9, 1};
  description.boxes.push_back(wall);
  const sim::World elsewhere(description);
  const cloud::PointCloud query = scan(elsewhere, sensor_pose(0, 0, 0), 0.01, 3);
  auto found = localizer_->localize(query.positions, SO3());
  ASSERT_FALSE(found.ok()) << found->T_map_sensor.translation().transpose() << " seen through " << found->seen_through_fraction;
  EXPECT_THAT(found.error().message, HasSubstr("map localization"));
}

TEST_F(MapLocalization, BadInputIsRefusedByName) {
  const cloud::PointCloud query = scan(*world_, sensor_pose(0, 0, 0), 0.01, 5);
  SO3 not_finite = SO3::from_wxyz(Eigen::Vector4d(std::nan(""), 0, 0, 0));
  EXPECT_THAT(localizer_->localize(query.positions, not_finite).error().message, HasSubstr("orientation is not finite"));
  MapLocalizationQuery far;
  far.T_map_sensor_guess = sensor_pose(500, 500, 0);
  EXPECT_THAT(localizer_->localize(query.positions, SO3(), far).error().message, HasSubstr("farther from the map"));
  EXPECT_THAT(localizer_->localize({}, SO3()).error().message, HasSubstr("returns 1-20 m around the sensor"));
  EXPECT_THAT(MapLocalizer::create({Eigen::Vector3f(1, 2, 3)}).error().message, HasSubstr("at least 50 needed"));
  MapLocalizerConfig bad;
  bad.slice_max_height = bad.slice_min_height;
  EXPECT_THAT(MapLocalizer::create(yard_map(*world_), bad).error().message, HasSubstr("slice_max_height"));
  // A map far larger than the grid may hold needs a guess.
  MapLocalizerConfig small;
  small.max_grid_cells = 1000;
  auto limited = MapLocalizer::create(yard_map(*world_), small, indoor_odometry());
  ASSERT_TRUE(limited.ok());
  EXPECT_THAT(limited->localize(query.positions, SO3()).error().message, HasSubstr("give a guess"));
}

}  // namespace
}  // namespace hanzo::fusion::lidar
