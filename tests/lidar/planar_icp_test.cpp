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

namespace hanzo::fusion::lidar {
namespace {

using ::testing::HasSubstr;

constexpr double kDegree = M_PI / 180.0;

struct Segment {
  Eigen::Vector2d a, b;
};

// A 12 x 8 m room with an inner wall stub and four square pillars (corners everywhere).
std::vector<Segment> room() {
  std::vector<Segment> walls = {{{0, 0}, {12, 0}}, {{12, 0}, {12, 8}}, {{12, 8}, {0, 8}}, {{0, 8}, {0, 0}}, {{6, 0}, {6, 3}}};
  for (const Eigen::Vector2d& centre : {Eigen::Vector2d(3, 5), Eigen::Vector2d(9, 5.5), Eigen::Vector2d(8.5, 2), Eigen::Vector2d(2, 2)}) {
    const double h = 0.25;
    const Eigen::Vector2d c00 = centre + Eigen::Vector2d(-h, -h), c10 = centre + Eigen::Vector2d(h, -h);
    const Eigen::Vector2d c11 = centre + Eigen::Vector2d(h, h), c01 = centre + Eigen::Vector2d(-h, h);
    walls.insert(walls.end(), {{c00, c10}, {c10, c11}, {c11, c01}, {c01, c00}});
  }
  return walls;
}

// A 40 m corridor, 2 m wide: walls only, or with door frames every 6 m. Seen with an 8 m range,
// so the ends stay out of sight.
std::vector<Segment> corridor(bool with_doors) {
  std::vector<Segment> walls = {{{-20, -1}, {20, -1}}, {{-20, 1}, {20, 1}}};
  if (with_doors) {
    for (double x = -18; x <= 18; x += 6) walls.push_back({{x, 1}, {x, 0.8}});
  }
  return walls;
}

// A 360-beam, 270 deg scan from `pose` (points in the laser frame, ranges below max_range).
PlanarPoints cast_scan(const std::vector<Segment>& walls, const SE2& pose, double max_range = 30.0) {
  PlanarPoints points;
  for (int beam = 0; beam < 360; ++beam) {
    const double angle = -135.0 * kDegree + beam * 0.75 * kDegree;
    const Eigen::Vector2d direction = pose.rotation_matrix() * Eigen::Vector2d(std::cos(angle), std::sin(angle));
    double nearest = max_range;
    for (const Segment& wall : walls) {
      const Eigen::Vector2d edge = wall.b - wall.a;
      const double denominator = direction.x() * edge.y() - direction.y() * edge.x();
      if (std::abs(denominator) < 1e-12) continue;
      const Eigen::Vector2d offset = wall.a - pose.translation();
      const double range = (offset.x() * edge.y() - offset.y() * edge.x()) / denominator;
      const double along = (offset.x() * direction.y() - offset.y() * direction.x()) / denominator;
      if (range > 0.05 && along >= 0 && along <= 1) nearest = std::min(nearest, range);
    }
    if (nearest < max_range) points.emplace_back(nearest * std::cos(angle), nearest * std::sin(angle));
  }
  return points;
}

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

  // Walls only: the Hessian's smallest eigenvalue (the axis) is far below the others (not zero:
  // the sparse far points have no line fit and add weak point-to-point terms).
  const std::vector<Segment> bare = corridor(false);
  const PlanarTarget bare_target = PlanarTarget::create(cast_scan(bare, T_world_target, 8.0)).value();
  const PlanarPoints bare_source = cast_scan(bare, T_world_source, 8.0);
  const PlanarIcpResult free_result = align_planar(bare_source, bare_target, guess).value();
  EXPECT_LT(free_result.hessian_eigenvalues(0), 0.02 * free_result.hessian_eigenvalues(1));
  // Across the corridor and in heading it is still exact.
  const SE2 free_error = truth.inverse() * free_result.T_target_source;
  EXPECT_LT(std::abs(free_error.translation().y()), 0.01);
  EXPECT_LT(std::abs(free_error.angle()), 0.05 * kDegree);

  // With a prior on the guess (5 cm) the weak axis stays near the guess instead of following
  // the few far points.
  PlanarIcpConfig with_prior;
  with_prior.guess_translation_sigma = 0.05;
  with_prior.guess_rotation_sigma = 0.02;
  const PlanarIcpResult held = align_planar(bare_source, bare_target, guess, with_prior).value();
  const double held_offset = (truth.inverse() * held.T_target_source).translation().x();
  EXPECT_GT(held_offset, 0.08);
  EXPECT_GT(held_offset, std::abs(free_error.translation().x()) + 0.05);

  // Door frames (no line-like neighbourhood at their ends) fix the axis through point-to-point
  // residuals, to the few centimetres their sampling allows (the guess was 15 cm off).
  const std::vector<Segment> doors = corridor(true);
  const PlanarTarget door_target = PlanarTarget::create(cast_scan(doors, T_world_target, 8.0)).value();
  const PlanarIcpResult fixed = align_planar(cast_scan(doors, T_world_source, 8.0), door_target, guess).value();
  const auto [translation, rotation] = error_of(fixed.T_target_source, truth);
  EXPECT_LT(translation, 0.03);
  EXPECT_LT(rotation, 0.1);
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
  auto pose_of = [&](size_t i) {
    const io::PoseMatrix& pose = log.report.scan_poses.poses[i];
    return SE2(std::atan2(pose(1, 0), pose(0, 0)), pose.block<2, 1>(0, 3));
  };
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
