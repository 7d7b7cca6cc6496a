// LoopClosureDetector on simulated scans of a yard with exact poses: a return to an earlier place
// is verified to within centimetres; a revisit (covered(): near the path through older
// keyframes) is told apart from a new place, a place seen recently and a place passed the other
// way; a searched revisit is forgotten.

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "hanzo/fusion/lidar/loop_closure.hpp"
#include "lidar/simulated_scan.hpp"

namespace hanzo::fusion::lidar {
namespace {

SE3 sensor_pose(double x, double y, double yaw) { return SE3(SO3::exp(Eigen::Vector3d(0, 0, yaw)), Eigen::Vector3d(x, y, 1.8)); }

struct Yard {
  sim::World world = testing_support::registration_world();
  std::vector<SE3> poses;
  LoopClosureDetector detector;

  explicit Yard(LoopClosureConfig config) : detector(config, LidarOdometryConfig{}) {}

  /// Adds a keyframe at `pose` after `path` metres.
  void add(const SE3& pose, double path) {
    std::vector<Eigen::Vector3f> points = testing_support::scan(world, pose, 0.01, static_cast<uint32_t>(poses.size())).positions;
    ASSERT_TRUE(detector.add_keyframe(std::move(points), path).ok());
    poses.push_back(pose);
  }
  LoopClosureDetector::PoseLookup lookup() const {
    return [this](std::size_t k) { return poses.at(k); };
  }
};

LoopClosureConfig yard_config() {
  LoopClosureConfig config;
  config.min_travel = 20.0;
  config.scan_context.exclude_recent = 2;
  config.scan_context.max_range = 40.0;
  config.scan_context.max_distance = 0.3;  // a small yard (scan_context_test.cpp)
  return config;
}

TEST(LoopClosure, RevisitsAreToldApartAndASearchedOneIsForgotten) {
  Yard yard(yard_config());
  // Out along the yard and back round: 8 keyframes 4 m apart (28 m of path).
  for (int i = 0; i < 8; ++i) yard.add(sensor_pose(-14.0 + 4.0 * i, i < 4 ? -1.0 : 2.0, 0.0), 4.0 * i);
  const double path = 40.0;
  const SE3 near_first = yard.poses[0] * SE3(SO3::exp(Eigen::Vector3d(0, 0, 0.1)), Eigen::Vector3d(0.3, 0.2, 0.0));
  EXPECT_TRUE(yard.detector.covered(near_first, path, yard.lookup()));
  EXPECT_FALSE(yard.detector.covered(near_first, 10.0, yard.lookup())) << "keyframe 0 lies only 10 m of path back";
  EXPECT_TRUE(yard.detector.covered(sensor_pose(-8.0, -0.5, 0.1), path, yard.lookup())) << "between keyframes 1 and 2, 4 m apart";
  EXPECT_FALSE(yard.detector.covered(sensor_pose(-8.0, 0.5, 0.0), path, yard.lookup())) << "1.5 m beside the path";
  EXPECT_FALSE(yard.detector.covered(yard.poses[0] * SE3(SO3(), Eigen::Vector3d(-1.5, 0.0, 0.0)), path, yard.lookup()))
      << "1.5 m behind the first keyframe";
  EXPECT_FALSE(yard.detector.covered(yard.poses[0] * SE3(SO3::exp(Eigen::Vector3d(0, 0, M_PI)), Eigen::Vector3d::Zero()), path,
                                     yard.lookup()))
      << "the same place passed the other way";
  LoopClosureConfig none = yard_config();
  none.covered_distance = 0.0;
  const LoopClosureDetector without(none, LidarOdometryConfig{});
  EXPECT_FALSE(without.covered(near_first, path, yard.lookup()));

  // The revisit searched: the loop to keyframe 0 (or a neighbour) verified to its true pose.
  yard.add(near_first, path);
  const std::optional<LoopClosure> loop = yard.detector.detect(yard.lookup());
  ASSERT_TRUE(loop.has_value());
  EXPECT_EQ(loop->to, 8U);
  const SE3 truth = yard.poses[loop->from].inverse() * near_first;
  EXPECT_LT((truth.inverse() * loop->T_from_to).translation().norm(), 0.05);
  EXPECT_LT((truth.inverse() * loop->T_from_to).rotation().log().norm(), 0.01);
  // ... then forgotten: the next keyframe takes its number and the detector's size is back.
  yard.detector.remove_newest();
  yard.poses.pop_back();
  EXPECT_EQ(yard.detector.size(), 8U);
  EXPECT_FALSE(yard.detector.detect(yard.lookup()).has_value()) << "nothing new to search";
  yard.add(sensor_pose(-14.0, -1.0, 0.05), path + 1.0);
  EXPECT_EQ(yard.detector.size(), 9U);
  EXPECT_TRUE(yard.detector.detect(yard.lookup()).has_value());

  LoopClosureConfig bad = yard_config();
  bad.covered_distance = -1.0;
  EXPECT_FALSE(bad.validate().ok());
}

}  // namespace
}  // namespace hanzo::fusion::lidar
