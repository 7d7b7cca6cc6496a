#include "hanzo/fusion/eval/pose_error.hpp"

#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/eval/association.hpp"

namespace hanzo::fusion::eval {
namespace {

using ::testing::HasSubstr;

io::PoseMatrix pose_at(const Eigen::Vector3d& position, double yaw) {
  io::PoseMatrix pose = io::PoseMatrix::Identity();
  pose.block<3, 3>(0, 0) = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.block<3, 1>(0, 3) = position;
  return pose;
}

// A 3D curve sampled at 10 Hz starting at t = 100 s.
io::Trajectory curve(std::size_t n) {
  io::Trajectory trajectory;
  for (std::size_t i = 0; i < n; ++i) {
    const double s = 0.1 * static_cast<double>(i);
    trajectory.timestamps.push_back(Timestamp::from_nanoseconds(100'000'000'000 + static_cast<int64_t>(i) * 100'000'000));
    trajectory.poses.push_back(pose_at(Eigen::Vector3d(5 * std::cos(s), 3 * std::sin(s), 0.2 * s), s));
  }
  return trajectory;
}

TEST(Statistics, MatchNumpyDefinitions) {
  const ErrorStatistics s = compute_statistics({1.0, 2.0, 4.0, 3.0});
  EXPECT_EQ(s.count, 4u);
  EXPECT_DOUBLE_EQ(s.mean, 2.5);
  EXPECT_DOUBLE_EQ(s.median, 2.5);
  EXPECT_DOUBLE_EQ(s.sse, 30.0);
  EXPECT_DOUBLE_EQ(s.rmse, std::sqrt(7.5));
  EXPECT_DOUBLE_EQ(s.std, std::sqrt(1.25));  // population std (ddof 0)
  EXPECT_DOUBLE_EQ(s.min, 1.0);
  EXPECT_DOUBLE_EQ(s.max, 4.0);
  EXPECT_DOUBLE_EQ(compute_statistics({3.0, 1.0, 2.0}).median, 2.0);
  EXPECT_EQ(compute_statistics({}).count, 0u);
}

TEST(Umeyama, RecoversAKnownSimilarity) {
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  const Eigen::Matrix3d rotation = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const Eigen::Vector3d translation(1, -2, 3);
  const double scale = 2.5;
  std::vector<Eigen::Vector3d> source, target;
  for (int i = 0; i < 50; ++i) {
    source.emplace_back(normal(rng), normal(rng), normal(rng));
    target.push_back(scale * rotation * source.back() + translation);
  }
  const auto sim3 = umeyama_alignment(source, target, true);
  ASSERT_TRUE(sim3.ok());
  EXPECT_TRUE(sim3->rotation.isApprox(rotation, 1e-12));
  EXPECT_TRUE(sim3->translation.isApprox(translation, 1e-12));
  EXPECT_NEAR(sim3->scale, scale, 1e-12);
  const auto se3 = umeyama_alignment(source, target, false);
  ASSERT_TRUE(se3.ok());
  EXPECT_EQ(se3->scale, 1.0);
  EXPECT_TRUE(se3->rotation.isApprox(rotation, 1e-12));  // rotation is scale independent
}

TEST(Umeyama, RejectsDegenerateAndMismatchedInput) {
  const std::vector<Eigen::Vector3d> line = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}};
  const auto degenerate = umeyama_alignment(line, line, false);
  ASSERT_FALSE(degenerate.ok());
  EXPECT_THAT(degenerate.error().message, HasSubstr("degenerate"));
  EXPECT_FALSE(umeyama_alignment(line, {{0, 0, 0}}, false).ok());
}

TEST(Ape, ZeroAfterAlignmentOfATransformedCopy) {
  const io::Trajectory reference = curve(200);
  io::Trajectory estimate = reference;
  estimate.transform(pose_at(Eigen::Vector3d(10, -4, 2), 1.1), 0.5);  // a Sim(3) away
  for (Alignment alignment : {Alignment::kSim3}) {
    ApeConfig config;
    config.alignment = alignment;
    for (PoseRelation relation : {PoseRelation::kTranslation, PoseRelation::kRotationAngleDeg, PoseRelation::kFull}) {
      config.relation = relation;
      const auto ape = compute_ape(reference, estimate, config);
      ASSERT_TRUE(ape.ok());
      EXPECT_LT(ape->statistics.max, 1e-9) << pose_relation_name(relation);
    }
  }
  ApeConfig se3;
  se3.alignment = Alignment::kSE3;
  EXPECT_GT(compute_ape(reference, estimate, se3)->statistics.rmse, 0.1);  // scale not corrected
  ApeConfig origin;
  origin.alignment = Alignment::kOrigin;
  origin.relation = PoseRelation::kRotationAngleDeg;
  EXPECT_LT(compute_ape(reference, estimate, origin)->statistics.max, 1e-9);  // rotation-only check
}

TEST(Ape, RelationsOfAKnownError) {
  io::Trajectory reference = curve(10);
  io::Trajectory estimate = reference;
  for (auto& pose : estimate.poses) pose = pose * pose_at(Eigen::Vector3d(0.3, 0.4, 0), 0.1);  // body-frame offset
  auto ape_with = [&](PoseRelation relation) {
    ApeConfig config;
    config.relation = relation;
    return compute_ape(reference, estimate, config)->statistics;
  };
  EXPECT_NEAR(ape_with(PoseRelation::kTranslation).mean, 0.5, 1e-12);
  EXPECT_NEAR(ape_with(PoseRelation::kRotationAngleRad).mean, 0.1, 1e-12);
  EXPECT_NEAR(ape_with(PoseRelation::kRotationAngleDeg).mean, 0.1 * 180 / M_PI, 1e-10);
  const double rot_part = std::sqrt(2 * (std::pow(std::cos(0.1) - 1, 2) + std::pow(std::sin(0.1), 2)));
  EXPECT_NEAR(ape_with(PoseRelation::kRotationPart).mean, rot_part, 1e-12);
  EXPECT_NEAR(ape_with(PoseRelation::kFull).mean, std::sqrt(rot_part * rot_part + 0.25), 1e-12);
}

TEST(Ape, TranslationAlignmentAndFirstNPoses) {
  const io::Trajectory reference = curve(100);
  io::Trajectory estimate = reference;
  estimate.transform(pose_at(Eigen::Vector3d(1, 2, 3), 0.0));
  ApeConfig config;
  config.alignment = Alignment::kTranslation;
  EXPECT_LT(compute_ape(reference, estimate, config)->statistics.max, 1e-12);
  // Break the second half; aligning on the first 50 poses still finds the exact offset.
  for (std::size_t i = 50; i < 100; ++i) estimate.poses[i](0, 3) += 1.0;
  config.alignment = Alignment::kSE3;
  config.align_num_poses = 50;
  const auto ape = compute_ape(reference, estimate, config);
  ASSERT_TRUE(ape.ok());
  EXPECT_LT(ape->errors[10], 1e-9);
  EXPECT_NEAR(ape->errors[80], 1.0, 1e-9);
}

TEST(Ape, RejectsTrajectoriesOfDifferentSize) {
  const auto ape = compute_ape(curve(10), curve(11));
  ASSERT_FALSE(ape.ok());
  EXPECT_THAT(ape.error().message, HasSubstr("10 vs 11"));
}

TEST(Rpe, PairSelectionFollowsEvo) {
  const io::Trajectory trajectory = curve(10);
  using Pairs = std::vector<std::pair<std::size_t, std::size_t>>;
  EXPECT_EQ(select_pairs(trajectory, 3, DeltaUnit::kFrames, false, 0.1), (Pairs{{0, 3}, {3, 6}, {6, 9}}));
  EXPECT_EQ(select_pairs(trajectory, 8, DeltaUnit::kFrames, true, 0.1), (Pairs{{0, 8}, {1, 9}}));
  // A straight line with 1 m steps: consecutive 2 m pairs start at the first index reaching 2 m.
  io::Trajectory line;
  for (int i = 0; i < 8; ++i) {
    line.timestamps.push_back(Timestamp::from_nanoseconds(i + 1));
    line.poses.push_back(pose_at(Eigen::Vector3d(i, 0, 0), 0));
  }
  EXPECT_EQ(select_pairs(line, 2, DeltaUnit::kMeters, false, 0.1), (Pairs{{2, 4}, {4, 6}}));
  EXPECT_EQ(select_pairs(line, 5, DeltaUnit::kMeters, true, 0.1), (Pairs{{0, 5}, {1, 6}, {2, 7}}));
}

TEST(Rpe, DriftPerStepIsMeasured) {
  const io::Trajectory reference = curve(101);
  io::Trajectory estimate = reference;
  // Each step's motion is off by 1 cm along body x: T_est_i = T_ref_i * Trans(0.01 i, 0, 0) would
  // not be a per-step error, so rebuild the estimate by composing perturbed relative motions.
  for (std::size_t i = 1; i < estimate.size(); ++i) {
    const io::PoseMatrix motion = reference.poses[i - 1].inverse() * reference.poses[i];
    estimate.poses[i] = estimate.poses[i - 1] * motion * pose_at(Eigen::Vector3d(0.01, 0, 0), 0);
  }
  RpeConfig config;  // delta 1 frame
  const auto rpe = compute_rpe(reference, estimate, config);
  ASSERT_TRUE(rpe.ok());
  EXPECT_EQ(rpe->pairs.size(), 100u);
  EXPECT_NEAR(rpe->statistics.max, 0.01, 1e-12);
  EXPECT_NEAR(rpe->statistics.min, 0.01, 1e-12);
}

TEST(Rpe, RejectsBadDeltas) {
  RpeConfig config;
  config.delta = 0;
  EXPECT_THAT(compute_rpe(curve(10), curve(10), config).error().message, HasSubstr("positive"));
  config.delta = 1.5;
  EXPECT_THAT(compute_rpe(curve(10), curve(10), config).error().message, HasSubstr("whole number"));
  config.delta = 100;
  config.delta_unit = DeltaUnit::kMeters;
  EXPECT_THAT(compute_rpe(curve(10), curve(10), config).error().message, HasSubstr("no pose pairs 100 m apart"));
}

TEST(Association, MatchesNearestWithinMaxDifferenceAndOffset) {
  io::Trajectory reference = curve(50);  // 10 Hz from 100 s
  io::Trajectory estimate;
  for (std::size_t i = 0; i < 50; i += 5) {  // 2 Hz, 3 ms late
    estimate.timestamps.push_back(reference.timestamps[i] + Duration::from_milliseconds(3));
    estimate.poses.push_back(reference.poses[i]);
  }
  const auto associated = associate(reference, estimate, {});
  ASSERT_TRUE(associated.ok());
  EXPECT_EQ(associated->estimate.size(), 10u);
  EXPECT_EQ(associated->reference_indices[3], 15u);
  AssociationConfig strict;
  strict.max_time_difference_s = 0.002;
  EXPECT_THAT(associate(reference, estimate, strict).error().message, HasSubstr("no matching timestamps"));
  strict.estimate_time_offset_s = -0.003;  // undo the latency
  const auto shifted = associate(reference, estimate, strict);
  ASSERT_TRUE(shifted.ok());
  EXPECT_EQ(shifted->estimate.size(), 10u);
  EXPECT_EQ(shifted->reference_indices[9], 45u);
}

// A dataset's ground truth in its own times (from 100 s here) and an estimate from the imported
// log (the same times + 1e9 s, starting later): paired with the importers' origin taken off.
// Otherwise, the first times are paired; overlapping or both-absolute times are left alone.
TEST(Association, GuessesTheOffsetBetweenRelativeAndAbsoluteTimes) {
  const io::Trajectory reference = curve(50);
  io::Trajectory estimate;
  for (std::size_t i = 7; i < 50; ++i) {
    estimate.timestamps.push_back(reference.timestamps[i] + Duration::from_seconds(kDefaultRelativeTimeOrigin_s));
    estimate.poses.push_back(reference.poses[i]);
  }
  const std::optional<TimeOffsetGuess> guess = guess_relative_time_offset(reference, estimate);
  ASSERT_TRUE(guess.has_value());
  EXPECT_EQ(guess->estimate_time_offset_s, -kDefaultRelativeTimeOrigin_s);
  EXPECT_THAT(guess->description, HasSubstr("importers' origin"));
  const auto paired = associate(reference, estimate, {0.01, guess->estimate_time_offset_s});
  ASSERT_TRUE(paired.ok());
  EXPECT_EQ(paired->estimate.size(), 43u);
  EXPECT_EQ(paired->reference_indices.front(), 7u);
  // The reverse: the reference absolute, the estimate relative.
  const std::optional<TimeOffsetGuess> reverse = guess_relative_time_offset(estimate, reference);
  ASSERT_TRUE(reverse.has_value());
  EXPECT_EQ(reverse->estimate_time_offset_s, kDefaultRelativeTimeOrigin_s);
  // Another origin: first time to first time.
  io::Trajectory elsewhere = reference;
  for (Timestamp& t : elsewhere.timestamps) t = t + Duration::from_seconds(1.7e9);
  const std::optional<TimeOffsetGuess> first_times = guess_relative_time_offset(reference, elsewhere);
  ASSERT_TRUE(first_times.has_value());
  EXPECT_NEAR(first_times->estimate_time_offset_s, -1.7e9, 1e-6);
  EXPECT_THAT(first_times->description, HasSubstr("first time with first time"));
  EXPECT_FALSE(guess_relative_time_offset(reference, reference).has_value());
  EXPECT_FALSE(guess_relative_time_offset(elsewhere, estimate).has_value());
}

}  // namespace
}  // namespace hanzo::fusion::eval
