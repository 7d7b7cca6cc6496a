#include "hanzo/fusion/eval/kitti_odometry.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::eval {
namespace {

// 1.2 km straight line along x sampled every metre.
io::Trajectory straight_line() {
  io::Trajectory trajectory;
  for (int i = 0; i <= 1200; ++i) {
    trajectory.timestamps.push_back(Timestamp::from_nanoseconds((i + 1) * 100'000'000LL));
    io::PoseMatrix pose = io::PoseMatrix::Identity();
    pose(0, 3) = i;
    trajectory.poses.push_back(pose);
  }
  return trajectory;
}

TEST(KittiOdometry, ScaleDriftIsItsPercentage) {
  const io::Trajectory ground_truth = straight_line();
  io::Trajectory estimate = ground_truth;
  for (auto& pose : estimate.poses) pose(0, 3) *= 1.01;  // 1 % too long
  const auto result = compute_kitti_odometry_error(ground_truth, estimate);
  ASSERT_TRUE(result.ok()) << result.error().message;
  // Segments end at the first frame strictly beyond the length: (L + 1) m, so the error is
  // 1 % of L + 1 over L.
  for (const auto& length : result->per_length) {
    EXPECT_NEAR(length.translation_error_percent, (length.length_m + 1) / length.length_m, 1e-9) << length.length_m;
    EXPECT_NEAR(length.rotation_error_deg_per_100m, 0.0, 1e-12);
  }
  EXPECT_EQ(result->per_length.size(), 8u);
  // 800 m segments start every 10 m while 801 m of path remain: 0, 10, ..., 390.
  EXPECT_EQ(result->per_length.back().segments, 40u);
}

TEST(KittiOdometry, HeadingDriftIsItsRate) {
  const io::Trajectory ground_truth = straight_line();
  io::Trajectory estimate = ground_truth;
  const double drift_rad_per_m = 1e-4;  // 0.573 deg per 100 m
  for (std::size_t i = 0; i < estimate.size(); ++i) {
    estimate.poses[i].block<3, 3>(0, 0) =
        Eigen::AngleAxisd(drift_rad_per_m * static_cast<double>(i), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  }
  const auto result = compute_kitti_odometry_error(ground_truth, estimate);
  ASSERT_TRUE(result.ok());
  for (const auto& length : result->per_length) {
    const double expected = drift_rad_per_m * (length.length_m + 1) / length.length_m * 180 / M_PI * 100;
    EXPECT_NEAR(length.rotation_error_deg_per_100m, expected, 1e-7);
  }
}

TEST(KittiOdometry, RejectsShortOrMismatchedTrajectories) {
  io::Trajectory short_line = straight_line();
  short_line.poses.resize(50);
  short_line.timestamps.resize(50);
  EXPECT_THAT(compute_kitti_odometry_error(short_line, short_line).error().message,
              ::testing::HasSubstr("shorter than every segment length"));
  EXPECT_FALSE(compute_kitti_odometry_error(straight_line(), short_line).ok());
}

}  // namespace
}  // namespace hanzo::fusion::eval
