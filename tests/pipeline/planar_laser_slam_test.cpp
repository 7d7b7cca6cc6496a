// 2D laser SLAM on the real Intel Research Lab log: odometry made 5 % too long and drifting
// 2 deg per metre, scan matching and loop closure bring the trajectory back onto the log's
// corrected poses.

#include <cmath>
#include <limits>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/io/carmen_import.hpp"
#include "hanzo/fusion/pipeline/planar_laser_slam.hpp"
#include "hanzo/fusion/sim/planar_odometry_error.hpp"
#include "support/planar_world.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using ::testing::HasSubstr;

io::Trajectory as_trajectory(const std::vector<Timestamp>& times, const std::vector<SE2>& poses) {
  io::Trajectory trajectory;
  for (size_t i = 0; i < poses.size(); ++i) {
    trajectory.timestamps.push_back(times[i]);
    trajectory.poses.push_back(io::pose_matrix(poses[i]));
  }
  return trajectory;
}

double ape_rmse(const io::Trajectory& reference, const io::Trajectory& estimate) {
  return eval::compute_ape(reference, estimate, {.relation = eval::PoseRelation::kTranslation, .alignment = eval::Alignment::kSE3})
      .value()
      .statistics.rmse;
}

TEST(PlanarLaserSlam, IntelLogWithCorruptedOdometryReturnsToTheCorrectedPoses) {
  const io::CarmenLog log = io::read_carmen(std::string(HANZO_DATA_DIR) + "/laser2d_carmen/intel-corrected.log.gz", {}).value();
  const io::Trajectory& reference = log.report.scan_poses;
  std::vector<SE2> truth;
  for (const io::PoseMatrix& pose : reference.poses) truth.push_back(io::planar_pose(pose));
  const std::vector<SE2> odometry = sim::corrupt_planar_odometry(truth, {.scale_error = 0.05, .heading_drift_per_meter = 2.0 * M_PI / 180.0});

  PlanarLaserSlam slam;
  for (size_t i = 0; i < log.scans.size(); ++i) ASSERT_TRUE(slam.add_scan(log.scans[i], odometry[i])) << "scan " << i;
  ASSERT_TRUE(slam.finish());

  const double odometry_rmse = ape_rmse(reference, as_trajectory(reference.timestamps, odometry));
  const double slam_rmse = ape_rmse(reference, slam.trajectory());
  const PlanarLaserSlamSummary& summary = slam.summary();
  std::printf("intel: odometry APE %.2f m, SLAM APE %.3f m; %zu keyframes, %zu loop closures (%zu candidates), %zu unmatched, %zu recovered; "
              "matching %.2f s, loops %.2f s, optimization %.2f s (%zu runs)\n",
              odometry_rmse, slam_rmse, summary.keyframes, summary.loop_closures, summary.loop_candidates, summary.unmatched_scans,
              summary.recovered_matches, summary.scan_matching_seconds, summary.loop_closure_seconds, summary.optimization_seconds,
              summary.optimizations);
  EXPECT_GT(odometry_rmse, 5.0);
  EXPECT_LT(slam_rmse, 0.2);
  EXPECT_GT(summary.loop_closures, 50U);
}

// A 40 m drive down a corridor (8 m range) with odometry 3 % too long: bare walls fix heading
// and the across position but not the position along the axis. The SLAM flags those scans
// degenerate and follows odometry along the axis instead of letting ICP slide or stick; door
// recesses every 6 m fix the axis.
TEST(PlanarLaserSlam, CorridorIsFlaggedDegenerateAndOdometryHoldsTheAxis) {
  for (const bool doors : {false, true}) {
    const std::vector<test_support::Segment> walls = test_support::corridor(doors, 60.0);
    std::vector<SE2> truth;
    for (int i = 0; i <= 100; ++i) truth.emplace_back(0.02 * std::sin(0.1 * i), Eigen::Vector2d(-40.0 + 0.4 * i, 0.3 * std::sin(0.05 * i)));
    const std::vector<SE2> odometry = sim::corrupt_planar_odometry(truth, {.scale_error = 0.03, .heading_drift_per_meter = 0.5 * M_PI / 180.0});
    PlanarLaserSlamConfig config;
    config.loop_closure = false;
    PlanarLaserSlam slam(config);
    double worst_across = 0.0, worst_heading = 0.0;
    SE2 last;
    for (size_t i = 0; i < truth.size(); ++i) {
      const PlanarScanEstimate estimate = slam.add_scan(Timestamp::from_seconds(1.0 + 0.1 * static_cast<double>(i)),
                                                        test_support::cast_scan(walls, truth[i], 8.0), odometry[i]).value();
      const SE2 error = truth[i].inverse() * estimate.T_map_laser;
      worst_across = std::max(worst_across, std::abs(estimate.T_map_laser.translation().y() - truth[i].translation().y()));
      worst_heading = std::max(worst_heading, std::abs(error.angle()));
      last = estimate.T_map_laser;
    }
    const PlanarLaserSlamSummary& summary = slam.summary();
    const double along_error = last.translation().x() - truth.back().translation().x();
    const double odometry_along_error = odometry.back().translation().x() - truth.back().translation().x();
    std::printf("corridor %s: %zu of %zu scans degenerate; along-axis error %.3f m (odometry %.3f m), across %.3f m, heading %.2f deg\n",
                doors ? "with doors" : "bare", summary.degenerate_scans, summary.scans, along_error, odometry_along_error, worst_across,
                worst_heading * 180.0 / M_PI);
    EXPECT_LT(worst_across, 0.05);
    EXPECT_LT(worst_heading, 0.5 * M_PI / 180.0);
    if (doors) {
      EXPECT_LT(summary.degenerate_scans, summary.scans / 2);
      EXPECT_LT(std::abs(along_error), 0.3);  // the recesses fix the axis (odometry alone: 1.2 m)
    } else {
      EXPECT_GT(summary.degenerate_scans, summary.scans * 9 / 10);
      // Along the axis the estimate follows odometry's scale (3 % of 40 m), not a slide.
      EXPECT_NEAR(along_error, 0.03 * 40.0, 0.1);
    }
  }
}

TEST(PlanarLaserSlam, BadScansAreRefusedAndChangeNothing) {
  const io::CarmenLog log = io::read_carmen(std::string(HANZO_DATA_DIR) + "/laser2d_carmen/intel-corrected.log.gz", {}).value();
  // Scans 150, 151, ... of the log (moving along a corridor).
  auto planar_points = [&](size_t i) {
    i += 150;
    lidar::PlanarPoints points;
    for (const Eigen::Vector3f& p : log.scans[i].points) points.emplace_back(p.x(), p.y());
    return points;
  };
  auto pose = [&](size_t i) { return io::planar_pose(log.report.scan_poses.poses[i + 150]); };
  auto scan = [&](size_t i) { return log.scans[i + 150]; };
  PlanarLaserSlam slam;
  ASSERT_TRUE(slam.add_scan(scan(0), pose(0)));
  ASSERT_TRUE(slam.add_scan(scan(1), pose(1)));
  const io::Trajectory before = slam.trajectory();

  EXPECT_THAT(slam.add_scan(scan(1).timestamp, planar_points(2), pose(2)).error().message, HasSubstr("does not increase"));
  EXPECT_THAT(slam.add_scan(scan(2).timestamp, {{1, 0}, {2, 0}}, pose(2)).error().message, HasSubstr("has 2 points (need 20)"));
  lidar::PlanarPoints with_nan = planar_points(2);
  with_nan[3].y() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(slam.add_scan(scan(2).timestamp, with_nan, pose(2)).error().message, HasSubstr("non-finite point"));
  EXPECT_THAT(slam.add_scan(scan(2).timestamp, planar_points(2), SE2(0.0, {std::nan(""), 0.0})).error().message,
              HasSubstr("odometry pose is not finite"));
  PlanarLaserSlamConfig bad;
  bad.keyframe_distance = 0;
  EXPECT_THAT(PlanarLaserSlam(bad).add_scan(scan(0), pose(0)).error().message, HasSubstr("keyframe_distance"));

  EXPECT_EQ(slam.summary().scans, 2U);
  EXPECT_EQ(slam.trajectory().poses, before.poses);
  // The next good scan goes on as if nothing had happened.
  const PlanarScanEstimate next = slam.add_scan(scan(2), pose(2)).value();
  EXPECT_TRUE(next.scan_matched);
  EXPECT_LT((pose(2).inverse() * next.T_map_laser).translation().norm(), 0.1);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
