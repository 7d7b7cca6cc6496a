#include "hanzo/fusion/io/trajectory.hpp"

#include <cstdio>
#include <filesystem>
#include <string>

#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::io {
namespace {

using ::testing::HasSubstr;

const std::string kData = std::string(HANZO_DATA_DIR) + "/trajectory_eval_evo/";

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("hanzo_trajectory_test_" + std::to_string(::getpid()) + "_" + name)).string();
}

TEST(ParseSeconds, PlainDecimalsAreExact) {
  EXPECT_EQ(parse_seconds("1311868164.363181")->nanoseconds(), 1311868164363181000);
  EXPECT_EQ(parse_seconds("0.000000001")->nanoseconds(), 1);
  EXPECT_EQ(parse_seconds("-1.5")->nanoseconds(), -1500000000);
  EXPECT_EQ(parse_seconds("12")->nanoseconds(), 12000000000);
  EXPECT_EQ(parse_seconds("1.037359e-01")->nanoseconds(), 103735900);
  EXPECT_FALSE(parse_seconds("abc").ok());
  EXPECT_FALSE(parse_seconds("1.5x").ok());
  EXPECT_FALSE(parse_seconds("nan").ok());
  // Beyond int64 nanoseconds (found by UBSan: the multiplication overflowed).
  EXPECT_NE(parse_seconds("17002000000").error().message.find("beyond"), std::string::npos);
  EXPECT_FALSE(parse_seconds("1e300").ok());
  EXPECT_EQ(format_seconds(Timestamp::from_nanoseconds(1311868164363181000)), "1311868164.363181");
  EXPECT_EQ(format_seconds(Timestamp::from_nanoseconds(2000000000)), "2");
}

TEST(Trajectory, ReadsTheEvoTestFiles) {
  const auto tum = read_trajectory(kData + "fr2_desk_groundtruth.txt", TrajectoryFormat::kTum);
  ASSERT_TRUE(tum.ok()) << tum.error().message;
  // SOURCE.md: 20957 poses (3 '#' header lines skipped); line 10863 repeats the time of 10862.
  EXPECT_EQ(tum->size(), 20956u);
  EXPECT_EQ(tum->dropped_duplicate_timestamps, 1u);
  EXPECT_EQ(tum->timestamps.front().nanoseconds(), 1311868163869700000);
  EXPECT_NEAR(tum->position(0).y(), -1.4217, 1e-15);

  const auto kitti = read_trajectory(kData + "KITTI_00_gt.txt", TrajectoryFormat::kKitti, kData + "KITTI_00_gt_times.txt");
  ASSERT_TRUE(kitti.ok()) << kitti.error().message;
  EXPECT_EQ(kitti->size(), 4541u);
  EXPECT_EQ(kitti->timestamps[1].nanoseconds(), 103735900);
  EXPECT_DOUBLE_EQ(kitti->poses[1](2, 3), 8.586941e-01);
  EXPECT_NEAR(kitti->path_length(), 3724.2, 0.5);  // KITTI 00 is 3.7 km
}

TEST(Trajectory, KittiRoundTripIsBitIdentical) {
  const auto original = read_trajectory(kData + "KITTI_00_ORB.txt", TrajectoryFormat::kKitti);
  ASSERT_TRUE(original.ok());
  const std::string path = temp_path("kitti.txt");
  ASSERT_TRUE(write_trajectory(path, *original, TrajectoryFormat::kKitti).ok());
  const auto again = read_trajectory(path, TrajectoryFormat::kKitti);
  ASSERT_TRUE(again.ok());
  ASSERT_EQ(again->size(), original->size());
  for (std::size_t i = 0; i < original->size(); ++i) ASSERT_EQ(again->poses[i], original->poses[i]) << i;
  std::remove(path.c_str());
}

TEST(Trajectory, TumAndEurocRoundTripKeepTimesAndPoses) {
  const auto original = read_trajectory(kData + "fr2_desk_ORB.txt", TrajectoryFormat::kTum);
  ASSERT_TRUE(original.ok());
  for (TrajectoryFormat format : {TrajectoryFormat::kTum, TrajectoryFormat::kEuroc}) {
    const auto again = parse_trajectory(format_trajectory(*original, format), format, "memory");
    ASSERT_TRUE(again.ok()) << again.error().message;
    ASSERT_EQ(again->size(), original->size());
    for (std::size_t i = 0; i < original->size(); ++i) {
      ASSERT_EQ(again->timestamps[i], original->timestamps[i]);
      ASSERT_TRUE(again->poses[i].isApprox(original->poses[i], 1e-14)) << i;
    }
  }
}

TEST(Trajectory, EurocGroundTruthWithExtraColumns) {
  const std::string text =
      "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z [], v_RS_R_x\n"
      "1403636579758555392,4.688319,-1.786938,0.783338,0.534108,-0.153029,-0.827383,-0.082152,-0.027876\n"
      "1403636579763555584,4.688177,-1.786770,0.787350,0.534640,-0.152990,-0.826976,-0.082863,-0.029272\n";
  const auto trajectory = parse_trajectory(text, TrajectoryFormat::kEuroc, "data.csv");
  ASSERT_TRUE(trajectory.ok()) << trajectory.error().message;
  ASSERT_EQ(trajectory->size(), 2u);
  EXPECT_EQ(trajectory->timestamps[1].nanoseconds(), 1403636579763555584);
  const Eigen::Quaterniond q(Eigen::Matrix3d(trajectory->poses[0].block<3, 3>(0, 0)));
  EXPECT_NEAR(std::abs(q.w()), 0.534108 / Eigen::Vector4d(0.534108, -0.153029, -0.827383, -0.082152).norm(), 1e-12);
}

TEST(Trajectory, RejectsBadInputNamingFileAndLine) {
  auto error_of = [](const std::string& text, TrajectoryFormat format) {
    auto result = parse_trajectory(text, format, "est.txt");
    return result.ok() ? std::string("ok") : result.error().message;
  };
  EXPECT_EQ(error_of("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n", TrajectoryFormat::kTum),
            "est.txt:2: expected 8 numbers for a tum pose, found 7");
  EXPECT_THAT(error_of("1 0 0 nan 0 0 0 1\n", TrajectoryFormat::kTum), HasSubstr("est.txt:1: non-finite"));
  EXPECT_THAT(error_of("1 0 0 0 0 0 0 0\n", TrajectoryFormat::kTum), HasSubstr("est.txt:1: zero quaternion"));
  EXPECT_THAT(error_of("2 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n", TrajectoryFormat::kTum),
              HasSubstr("est.txt:2: timestamp 1 goes back in time (previous 2)"));
  EXPECT_THAT(error_of("1 0 0 x 0 0 0 1\n", TrajectoryFormat::kTum), HasSubstr("est.txt:1: column 4: 'x' is not a number"));
  EXPECT_THAT(error_of("1.5,0,0,0,1,0,0,0\n", TrajectoryFormat::kEuroc), HasSubstr("integer nanoseconds"));
  EXPECT_EQ(error_of("# only a comment\n", TrajectoryFormat::kTum), "est.txt: no poses");
  EXPECT_THAT(read_trajectory("/nonexistent/poses.txt", TrajectoryFormat::kKitti).error().message,
              HasSubstr("/nonexistent/poses.txt: cannot open file"));
  EXPECT_FALSE(trajectory_format_from_name("csv").ok());
}

TEST(Trajectory, RepeatedTimestampKeepsTheFirstPose) {
  const auto trajectory = parse_trajectory("1 0 0 0 0 0 0 1\n1 5 0 0 0 0 0 1\n2 1 0 0 0 0 0 1\n", TrajectoryFormat::kTum, "gt");
  ASSERT_TRUE(trajectory.ok());
  ASSERT_EQ(trajectory->size(), 2u);
  EXPECT_EQ(trajectory->position(0).x(), 0.0);
  EXPECT_EQ(trajectory->dropped_duplicate_timestamps, 1u);
}

TEST(Trajectory, KittiTimesMustMatchThePoses) {
  const std::vector<Timestamp> times = {Timestamp::from_nanoseconds(0)};
  const std::string two_poses = "1 0 0 0 0 1 0 0 0 0 1 0\n1 0 0 1 0 1 0 0 0 0 1 0\n";
  const auto result = parse_trajectory(two_poses, TrajectoryFormat::kKitti, "poses.txt", &times);
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result.error().message, HasSubstr("more poses than the 1 times given"));
}

TEST(Trajectory, TransformAppliesScaleThenRigidMotion) {
  Trajectory trajectory;
  trajectory.timestamps = {Timestamp::from_nanoseconds(1)};
  PoseMatrix pose = PoseMatrix::Identity();
  pose(0, 3) = 1.0;
  trajectory.poses = {pose};
  PoseMatrix T = PoseMatrix::Identity();
  T.block<3, 3>(0, 0) = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  T(2, 3) = 5.0;
  trajectory.transform(T, 2.0);
  EXPECT_TRUE(trajectory.position(0).isApprox(Eigen::Vector3d(0, 2, 5), 1e-12));
}

}  // namespace
}  // namespace hanzo::fusion::io
