// Camera sessions joined into one keyframe graph (pipeline/session_merge.hpp) on real images:
// KITTI odometry 06 (a suburban street, 60 m straight) cut into two monocular sessions that
// overlap in the middle: frames 0-32 and 18-50. Each session's map has its own frame (its first
// camera) and its own scale (its first baseline). The second joins the first by bag-of-words
// candidates and landmark alignment (a similarity: scale included), and every keyframe of the
// merged map lies on the true path (after one similarity for the whole map, as monocular maps
// need). A map of another street (KITTI raw 0052) is refused with the reason.

#include <chrono>
#include <cstdio>

#include <gtest/gtest.h>

#include "camera_session_maps.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/pipeline/session_merge.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using testing::camera_session_map;
using testing::keyframe_errors;
using testing::keyframe_positions;

/// The map in another frame at another scale: x' = scale R x + t.
msgs::FusionMap moved(msgs::FusionMap map, double scale, const SE3& T) {
  for (Eigen::Vector3f& position : map.visual_landmarks->positions) position = (T * (scale * position.cast<double>())).cast<float>();
  for (float& sigma : map.visual_landmarks->position_std) sigma *= static_cast<float>(scale);
  for (msgs::VisualKeyframe& keyframe : map.visual_landmarks->keyframes) {
    const SE3 pose = keyframe.T_world_camera.to_se3();
    keyframe.T_world_camera = msgs::Pose::from_se3(T * SE3(pose.rotation(), scale * pose.translation()));
  }
  return map;
}

TEST(VisualSessionMerge, TwoMonocularSessionsOfAStreetJoinAtTheirScaleAndAnotherStreetIsRefused) {
  const vision::sequences::Sequence street = vision::sequences::kitti_odometry_06();
  const testing::CameraSessionMap a = camera_session_map(street, 0, 32, "first");
  const testing::CameraSessionMap b = camera_session_map(street, 18, 50, "second");
  EXPECT_TRUE(a.map.visual_landmarks->scale_free && b.map.visual_landmarks->scale_free);
  const auto start = std::chrono::steady_clock::now();
  const Result<SessionMergeResult> merged = merge_sessions({a.map, b.map});
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(merged) << merged.error().message;
  ASSERT_EQ(merged->joins.size(), 1U);
  std::printf("joined: %zu of %zu visual keyframes aligned, %zu loops; scale %.3f; chi2 %.1f -> %.1f; %.2f s\n", merged->visual_verified,
              merged->visual_queries, merged->inter_session_loops, merged->joins[0].scale, merged->initial_chi2, merged->final_chi2, seconds);
  EXPECT_GE(merged->inter_session_loops, 3U);

  const msgs::VisualLandmarkLayer& layer = merged->merged.visual_landmarks.value();
  ASSERT_EQ(layer.keyframes.size(), a.keyframe_truth.size() + b.keyframe_truth.size());
  EXPECT_EQ(layer.sources, (std::vector<std::string>{"first", "second"}));
  EXPECT_EQ(layer.positions.size(), a.map.visual_landmarks->positions.size() + b.map.visual_landmarks->positions.size());
  EXPECT_TRUE(layer.scale_free);
  std::vector<Eigen::Vector3d> truth = a.keyframe_truth;
  truth.insert(truth.end(), b.keyframe_truth.begin(), b.keyframe_truth.end());
  const auto [mean, worst] = keyframe_errors(keyframe_positions(layer), truth);
  const auto [mean_a, worst_a] = keyframe_errors(keyframe_positions(*a.map.visual_landmarks), a.keyframe_truth);
  const auto [mean_b, worst_b] = keyframe_errors(keyframe_positions(*b.map.visual_landmarks), b.keyframe_truth);
  std::printf("%zu keyframes over 60 m: mean %.3f m, max %.3f m from the truth (each session alone over 38 m: mean %.3f / %.3f, max %.3f / %.3f)\n",
              truth.size(), mean, worst, mean_a, mean_b, worst_a, worst_b);
  EXPECT_LT(worst, 0.5);

  // The same second session in another frame at 2.5 times its scale joins at 2.5 times the scale.
  const SE3 elsewhere(SO3::from_axis_angle(Eigen::Vector3d(0.3, -1.0, 0.2).normalized(), 2.0), Eigen::Vector3d(40.0, -7.0, 3.0));
  const Result<SessionMergeResult> rescaled = merge_sessions({a.map, moved(b.map, 2.5, elsewhere)});
  ASSERT_TRUE(rescaled) << rescaled.error().message;
  EXPECT_NEAR(rescaled->joins[0].scale, merged->joins[0].scale / 2.5, 0.02 * merged->joins[0].scale / 2.5);
  EXPECT_LT(keyframe_errors(keyframe_positions(*rescaled->merged.visual_landmarks), truth).second, 0.5);

  const msgs::FusionMap reread = maps::parse_fusion_map(maps::serialize_fusion_map(merged->merged, {.chunk_bytes = 1 << 16}).value()).value();
  ASSERT_TRUE(reread.visual_landmarks);
  EXPECT_EQ(reread.visual_landmarks->sources, layer.sources);
  EXPECT_TRUE(reread.visual_landmarks->scale_free);
  EXPECT_EQ(reread.visual_landmarks->keyframes.back().source, 1U);

  const testing::CameraSessionMap other = camera_session_map(vision::sequences::kitti_raw_0052(), 0, 30, "other");
  const Result<SessionMergeResult> refused = merge_sessions({a.map, other.map});
  ASSERT_FALSE(refused) << "joined another street";
  std::printf("another street: %s\n", refused.error().message.c_str());
  EXPECT_NE(refused.error().message.find("other not joined to first"), std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
