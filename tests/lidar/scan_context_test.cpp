// Scan Context place recognition on simulated scans of a yard with exact poses: a revisit with
// another heading is found and its yaw recovered, GICP started from that yaw closes the loop,
// other places do not match, bad input is refused.

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/lidar/registration.hpp"
#include "hanzo/fusion/lidar/scan_context.hpp"
#include "lidar/simulated_scan.hpp"

namespace hanzo::fusion::lidar {
namespace {

using ::testing::HasSubstr;

SE3 sensor_pose(double x, double y, double yaw) {
  return SE3(SO3::exp(Eigen::Vector3d(0, 0, yaw)), Eigen::Vector3d(x, y, 1.8));
}

TEST(ScanContext, RevisitWithAnotherHeadingIsFoundAndRegistrationClosesTheLoop) {
  const sim::World world = testing_support::registration_world();
  ScanContextConfig config;
  config.exclude_recent = 0;
  config.max_range = 40.0;
  config.max_distance = 0.3;  // a small yard: a 0.5 m offset moves points across 2 m rings (measured 0.19, others >= 0.47)
  ScanContextDatabase database(config);
  // Keyframes along a path through the yard, 4 m apart.
  std::vector<SE3> places;
  for (int i = 0; i < 8; ++i) places.push_back(sensor_pose(-14.0 + 4.0 * i, (i % 2 ? 2.0 : -1.0), 0.3 * i));
  for (size_t i = 0; i < places.size(); ++i) {
    ASSERT_TRUE(database.add(i, make_scan_context(testing_support::scan(world, places[i], 0.01, static_cast<uint32_t>(i)), config).value()));
  }
  // Back at place 3, 0.4 m off and turned by 100 deg.
  const SE3 revisit = places[3] * SE3(SO3::exp(Eigen::Vector3d(0, 0, 100.0 * M_PI / 180.0)), Eigen::Vector3d(0.4, -0.3, 0.0));
  const cloud::PointCloud query_scan = testing_support::scan(world, revisit, 0.01, 99);
  const ScanContext query = make_scan_context(query_scan, config).value();
  const std::optional<ScanContextMatch> match = database.query(query).value();
  ASSERT_TRUE(match.has_value());
  EXPECT_EQ(match->id, 3U);
  const double true_yaw = 100.0 * M_PI / 180.0;
  EXPECT_LT(std::abs(std::remainder(match->distance.yaw - true_yaw, 2 * M_PI)), 8.0 * M_PI / 180.0);  // within about a sector
  // Every other place is farther in descriptor distance.
  double nearest_other = 1.0;
  for (size_t i = 0; i < places.size(); ++i) {
    if (i == 3) continue;
    const ScanContext other = make_scan_context(testing_support::scan(world, places[i], 0.01, static_cast<uint32_t>(i)), config).value();
    nearest_other = std::min(nearest_other, scan_context_distance(query, other).value().distance);
  }
  std::printf("scan context: revisit distance %.3f (yaw %.1f deg, true 100), nearest other place %.3f\n", match->distance.distance,
              match->distance.yaw * 180.0 / M_PI, nearest_other);
  EXPECT_GT(nearest_other, match->distance.distance + 0.05);

  // Verification: GICP from the descriptor's yaw recovers T_place_revisit.
  const cloud::PointCloud place_scan = testing_support::scan(world, places[3], 0.01, 3);
  const SE3 guess(SO3::exp(Eigen::Vector3d(0, 0, match->distance.yaw)), Eigen::Vector3d::Zero());
  RegistrationConfig registration;
  registration.coarse_correspondence_distances = {3.0};
  const RegistrationResult result = register_clouds(query_scan, place_scan, guess, registration).value();
  const SE3 error = (places[3].inverse() * revisit).inverse() * result.T_target_source;
  EXPECT_LT(error.translation().norm(), 0.05);
  EXPECT_LT(error.rotation().log().norm(), 1.0 * M_PI / 180.0);
}

TEST(ScanContext, DistanceIsRotationInvariantAndExcludesRecentEntries) {
  const sim::World world = testing_support::registration_world();
  ScanContextConfig config;
  config.max_range = 40.0;
  const cloud::PointCloud scan = testing_support::scan(world, sensor_pose(2.0, 1.0, 0.0), 0.0, 1);
  const ScanContext a = make_scan_context(scan, config).value();
  // The same scan rotated by exactly 10 sectors (60 deg) about z: the same bins, shifted.
  cloud::PointCloud rotated = scan;
  const Eigen::Matrix3f R = SO3::exp(Eigen::Vector3d(0, 0, 60.0 * M_PI / 180.0)).matrix().cast<float>();
  for (Eigen::Vector3f& p : rotated.positions) p = R.transpose() * p;  // the sensor turned +60 deg
  const ScanContext b = make_scan_context(rotated, config).value();
  const ScanContextDistance distance = scan_context_distance(b, a).value();
  EXPECT_LT(distance.distance, 0.02);
  EXPECT_NEAR(distance.yaw, 60.0 * M_PI / 180.0, 6.1 * M_PI / 180.0);
  EXPECT_LT((a.ring_key - b.ring_key).norm(), 0.05);

  config.exclude_recent = 1;
  ScanContextDatabase database(config);
  ASSERT_TRUE(database.add(7, a));
  EXPECT_FALSE(database.query(b).value().has_value());  // the only entry is too recent
  ASSERT_TRUE(database.add(8, a));
  ASSERT_TRUE(database.query(b).value().has_value());
  EXPECT_EQ(database.query(b).value()->id, 7U);
}

TEST(ScanContext, BadInputIsRefusedByName) {
  ScanContextConfig config;
  EXPECT_THAT(make_scan_context(cloud::PointCloud{}, config).error().message, HasSubstr("none of the 0 points"));
  cloud::PointCloud far;
  far.positions = {Eigen::Vector3f(500, 0, 0), Eigen::Vector3f(std::nanf(""), 0, 0)};
  EXPECT_THAT(make_scan_context(far, config).error().message, HasSubstr("within 80 m"));
  ScanContextConfig bad = config;
  bad.num_sectors = 0;
  EXPECT_THAT(make_scan_context(far, bad).error().message, HasSubstr("num_sectors"));
  cloud::PointCloud near;
  near.positions = {Eigen::Vector3f(5, 1, 0)};
  const ScanContext small = make_scan_context(near, config).value();
  ScanContextConfig other = config;
  other.num_rings = 10;
  const ScanContext different = make_scan_context(near, other).value();
  EXPECT_THAT(scan_context_distance(small, different).error().message, HasSubstr("20x60 and 10x60"));
  ScanContextDatabase database(config);
  EXPECT_THAT(database.add(1, different).error().message, HasSubstr("expected 20x60"));
  EXPECT_THAT(database.query(different).error().message, HasSubstr("10 rings, expected 20"));
}

}  // namespace
}  // namespace hanzo::fusion::lidar
