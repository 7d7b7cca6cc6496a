// Camera sessions of learned features joined (pipeline/session_merge.hpp): KITTI odometry 06 cut
// into two monocular sessions (frames 0-32 and 18-50) mapped with ALIKED-t16; candidates come
// from the shipped VLAD model of its descriptors, verification from the landmarks' float
// descriptors. The second joins at its scale and the merged keyframes lie on the true path.

#include <cstdio>

#include <gtest/gtest.h>

#include "hanzo/fusion/ai/learned_features.hpp"
#include "hanzo/fusion/pipeline/session_merge.hpp"
#include "pipeline/camera_session_maps.hpp"

namespace hanzo::fusion::ai {
namespace {

TEST(LearnedSessionMerge, TwoAlikedSessionsOfAStreetJoinByVladCandidates) {
  LearnedFeatureConfig features;
  features.model = LearnedModel::kAlikedT16;
  features.model_path = std::string(HANZO_MODELS_DIR) + "/aliked/aliked-t16.pth";
  features.max_keypoints = 2000;
  vision::VisualOdometryConfig config;
  config.extractor = LearnedFeatureExtractor::load(features).value();
  const vision::sequences::Sequence street = vision::sequences::kitti_odometry_06();
  const testing::CameraSessionMap a = testing::camera_session_map(street, 0, 32, "first", config);
  const testing::CameraSessionMap b = testing::camera_session_map(street, 18, 50, "second", config);
  ASSERT_EQ(a.map.visual_landmarks->descriptor_type, "aliked-t16");

  const Result<pipeline::SessionMergeResult> merged = pipeline::merge_sessions({a.map, b.map});
  ASSERT_TRUE(merged) << merged.error().message;
  std::vector<Eigen::Vector3d> truth = a.keyframe_truth;
  truth.insert(truth.end(), b.keyframe_truth.begin(), b.keyframe_truth.end());
  const auto [mean, worst] = testing::keyframe_errors(testing::keyframe_positions(*merged->merged.visual_landmarks), truth);
  std::printf("aliked-t16: %zu of %zu visual keyframes aligned, %zu loops, scale %.3f; %zu keyframes: mean %.3f m, max %.3f m from the truth\n",
              merged->visual_verified, merged->visual_queries, merged->inter_session_loops, merged->joins.at(0).scale, truth.size(), mean, worst);
  EXPECT_GE(merged->inter_session_loops, 3U);
  EXPECT_EQ(merged->merged.visual_landmarks->descriptor_type, "aliked-t16");
  EXPECT_EQ(merged->merged.visual_landmarks->float_descriptors.size(),
            a.map.visual_landmarks->float_descriptors.size() + b.map.visual_landmarks->float_descriptors.size());
  EXPECT_LT(worst, 0.5);
}

}  // namespace
}  // namespace hanzo::fusion::ai
