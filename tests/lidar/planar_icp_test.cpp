// Planar scan matching: point-to-line ICP and correlative search on simulated scans with exact
// ground truth (a room, a corridor) and on consecutive scans of the real Intel Research Lab log.

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/io/carmen_import.hpp"
#include "hanzo/fusion/lidar/correlative_scan_matcher.hpp"
#include "hanzo/fusion/lidar/planar_icp.hpp"
#include "support/planar_world.hpp"

namespace hanzo::fusion::lidar {
namespace {

using ::testing::HasSubstr;
using test_support::cast_scan;
using test_support::corridor;
using test_support::room;
using test_support::Segment;

constexpr double kDegree = M_PI / 180.0;

// T_target_source error as (translation m, |rotation| deg).
std::pair<double, double> error_of(const SE2& estimate, const SE2& truth) {
  const SE2 error = truth.inverse() * estimate;
  return {error.translation().norm(), std::abs(error.angle()) / kDegree};
}

TEST(PlanarIcp, RecoversASimulatedPairExactly) {
  const std::vector<Segment> walls = room();
  const SE2 T_world_target(0.3, {4.0, 4.0}), T_world_source(0.6, {5.2, 3.6});
  const SE2 truth = T_world_target.inverse() * T_world_source;
  const PlanarTarget target = PlanarTarget::create(cast_scan(walls, T_world_target)).value();
  const PlanarPoints source = cast_scan(walls, T_world_source);
  for (const SE2& perturbation : {SE2(), SE2(5 * kDegree, {0.3, -0.2}), SE2(-8 * kDegree, {-0.4, 0.3})}) {
    const PlanarIcpResult result = align_planar(source, target, truth * perturbation).value();
    const auto [translation, rotation] = error_of(result.T_target_source, truth);
    EXPECT_TRUE(result.converged);
    EXPECT_LT(translation, 0.01);
    EXPECT_LT(rotation, 0.05);
    EXPECT_GT(result.fitness, 0.85);
    EXPECT_LT(result.inlier_rmse, 0.03);  // point-to-point residuals at corners see the sampling
  }
}

TEST(PlanarIcp, CorridorWallsLeaveTheAxisFreeAndThePriorHoldsIt) {
  const SE2 T_world_target(0.0, {0.0, 0.0}), T_world_source(0.02, {1.0, 0.1});
  const SE2 truth = T_world_target.inverse() * T_world_source;
  const SE2 guess = truth * SE2(0.0, {0.15, 0.0});  // 15 cm off along the corridor

  // Walls only: nothing fixes the axis. The translation's marginal information is degenerate
  // and the estimate stays where the guess put it along the axis (the sparse far points, which
  // would hold a moving sensor back, are not in the target); across and in heading it is exact.
  const std::vector<Segment> bare = corridor(false);
  const PlanarTarget bare_target = PlanarTarget::create(cast_scan(bare, T_world_target, 8.0)).value();
  const PlanarPoints bare_source = cast_scan(bare, T_world_source, 8.0);
  const PlanarIcpResult free_result = align_planar(bare_source, bare_target, guess).value();
  Eigen::Vector2d weak_direction;
  EXPECT_LT(translation_constraint_ratio(free_result.information, &weak_direction), 1e-3);
  EXPECT_GT(std::abs(weak_direction.x()), 0.99);
  const SE2 free_error = truth.inverse() * free_result.T_target_source;
  EXPECT_NEAR(free_error.translation().x(), 0.15, 0.01);
  EXPECT_LT(std::abs(free_error.translation().y()), 0.01);
  EXPECT_LT(std::abs(free_error.angle()), 0.05 * kDegree);

  // Door recesses (corners, short walls across the axis) fix it: from 15 cm off to within
  // 2 cm of the truth, and the translation is well constrained.
  const std::vector<Segment> doors = corridor(true);
  const PlanarTarget door_target = PlanarTarget::create(cast_scan(doors, T_world_target, 8.0)).value();
  const PlanarPoints door_source = cast_scan(doors, T_world_source, 8.0);
  const PlanarIcpResult fixed = align_planar(door_source, door_target, guess).value();
  const auto [translation, rotation] = error_of(fixed.T_target_source, truth);
  EXPECT_LT(translation, 0.02);  // the corners' sampling differs between the two poses
  EXPECT_LT(rotation, 0.05);
  EXPECT_GT(translation_constraint_ratio(fixed.information), 0.02);

  // A tight prior on the guess (1 mm) holds the estimate there against the doors.
  PlanarIcpConfig with_prior;
  with_prior.guess_translation_sigma = 0.001;
  with_prior.guess_rotation_sigma = 0.001;
  const PlanarIcpResult held = align_planar(door_source, door_target, guess, with_prior).value();
  EXPECT_NEAR((truth.inverse() * held.T_target_source).translation().x(), 0.15, 0.02);
}

TEST(CorrelativeScanMatcher, FindsAPoseFarOutsideIcpsReachThenIcpRefinesIt) {
  const std::vector<Segment> walls = room();
  const SE2 T_world_target(0.0, {4.0, 4.5}), T_world_source(0.0, {4.5, 4.0});
  const SE2 truth = T_world_target.inverse() * T_world_source;
  const PlanarPoints target_points = cast_scan(walls, T_world_target);
  const PlanarPoints source = cast_scan(walls, T_world_source);
  const SE2 guess = truth * SE2(15 * kDegree, {0.8, -0.6});

  const CorrelativeScanMatch coarse = correlative_scan_match(source, target_points, guess, {}).value();
  const auto [coarse_translation, coarse_rotation] = error_of(coarse.T_target_source, truth);
  EXPECT_LT(coarse_translation, 0.08);
  EXPECT_LT(coarse_rotation, 1.0);
  EXPECT_GT(coarse.score, 0.8);

  const PlanarTarget target = PlanarTarget::create(target_points).value();
  const PlanarIcpResult refined = align_planar(source, target, coarse.T_target_source).value();
  const auto [translation, rotation] = error_of(refined.T_target_source, truth);
  EXPECT_LT(translation, 0.01);
  EXPECT_LT(rotation, 0.05);
}

TEST(CorrelativeScanMatcher, BranchAndBoundFindsTheExhaustiveOptimum) {
  const std::vector<Segment> walls = room();
  CorrelativeScanMatcherConfig exhaustive;
  exhaustive.branch_and_bound = false;
  exhaustive.linear_window = 0.6;
  exhaustive.angular_window = 0.1;
  CorrelativeScanMatcherConfig bounded = exhaustive;
  bounded.branch_and_bound = true;
  for (int trial = 0; trial < 6; ++trial) {
    const SE2 T_world_target(0.2 * trial, {3.0 + 0.7 * trial, 3.0 + 0.3 * trial}), T_world_source(0.2 * trial + 0.05, {3.4 + 0.7 * trial, 3.2 + 0.3 * trial});
    const PlanarPoints target = cast_scan(walls, T_world_target), source = cast_scan(walls, T_world_source);
    const SE2 guess = T_world_target.inverse() * T_world_source * SE2(0.04 * (trial - 3), {0.1 * trial - 0.3, 0.25 - 0.1 * trial});
    const CorrelativeScanMatch all = correlative_scan_match(source, target, guess, exhaustive).value();
    const CorrelativeScanMatch fast = correlative_scan_match(source, target, guess, bounded).value();
    EXPECT_NEAR(fast.score, all.score, 1e-6) << "trial " << trial;
    EXPECT_LT((all.T_target_source.inverse() * fast.T_target_source).log().norm(), 1e-9) << "trial " << trial;
    EXPECT_LT(fast.poses_evaluated * 4, all.poses_evaluated) << "trial " << trial;
  }
}

// Consecutive scans of the Intel lab (0.55 m and 18 deg apart on average), matched from the
// relative pose of the log's corrected poses moved by 0.1 m / 3 deg, land back on it. The
// corrected poses are themselves a SLAM result, so the bound is a few centimetres.
TEST(PlanarIcp, ConsecutiveIntelScansMatchTheCorrectedPoses) {
  const io::CarmenLog log = io::read_carmen(std::string(HANZO_DATA_DIR) + "/laser2d_carmen/intel-corrected.log.gz", {}).value();
  auto points_of = [&](size_t i) {
    PlanarPoints points;
    for (const Eigen::Vector3f& p : log.scans[i].points) points.emplace_back(p.x(), p.y());
    return points;
  };
  auto pose_of = [&](size_t i) { return io::planar_pose(log.report.scan_poses.poses[i]); };
  std::vector<double> translation_errors, rotation_errors;
  for (size_t i = 0; i + 1 < log.scans.size(); i += 10) {
    const SE2 truth = pose_of(i).inverse() * pose_of(i + 1);
    const PlanarTarget target = PlanarTarget::create(points_of(i)).value();
    const PlanarIcpResult result = align_planar(points_of(i + 1), target, truth * SE2(3 * kDegree, {0.1, -0.05})).value();
    const auto [translation, rotation] = error_of(result.T_target_source, truth);
    translation_errors.push_back(translation);
    rotation_errors.push_back(rotation);
  }
  auto median = [](std::vector<double> values) {
    std::nth_element(values.begin(), values.begin() + static_cast<long>(values.size() / 2), values.end());
    return values[values.size() / 2];
  };
  auto fraction_below = [](const std::vector<double>& values, double bound) {
    return static_cast<double>(std::count_if(values.begin(), values.end(), [&](double v) { return v < bound; })) / static_cast<double>(values.size());
  };
  EXPECT_LT(median(translation_errors), 0.03);
  EXPECT_LT(median(rotation_errors), 0.5);
  EXPECT_GT(fraction_below(translation_errors, 0.1), 0.95);
  EXPECT_GT(fraction_below(rotation_errors, 2.0), 0.95);
}

TEST(PlanarIcp, BadInputIsRefusedByName) {
  const std::vector<Segment> walls = room();
  const PlanarPoints scan = cast_scan(walls, SE2(0.0, {4.0, 4.0}));
  EXPECT_THAT(PlanarTarget::create({}).error().message, HasSubstr("target is empty"));
  PlanarPoints with_nan = scan;
  with_nan[7].x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THAT(PlanarTarget::create(with_nan).error().message, HasSubstr("target point 7 is not finite"));
  const PlanarTarget target = PlanarTarget::create(scan).value();
  EXPECT_THAT(align_planar(with_nan, target, SE2()).error().message, HasSubstr("source point 7 is not finite"));
  EXPECT_THAT(align_planar(scan, target, SE2(0.0, {50.0, 0.0})).error().message, HasSubstr("at the initial guess"));
  PlanarIcpConfig bad;
  bad.max_correspondence_distance = -1;
  EXPECT_THAT(align_planar(scan, target, SE2(), bad).error().message, HasSubstr("max_correspondence_distance"));
  // Three collinear points have a line but no pose: fewer than 3 correspondences is refused.
  EXPECT_FALSE(align_planar({{100, 0}, {101, 0}}, target, SE2()));

  CorrelativeScanMatcherConfig bad_search;
  bad_search.resolution = 0;
  EXPECT_THAT(correlative_scan_match(scan, scan, SE2(), bad_search).error().message, HasSubstr("resolution"));
  EXPECT_THAT(correlative_scan_match({}, scan, SE2(), {}).error().message, HasSubstr("empty"));
  PlanarPoints huge = scan;
  huge.emplace_back(1e6, 1e6);
  EXPECT_THAT(correlative_scan_match(scan, huge, SE2(), {}).error().message, HasSubstr("cells"));
}

}  // namespace
}  // namespace hanzo::fusion::lidar
