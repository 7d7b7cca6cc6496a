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
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/eval/alignment.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/pipeline/session_merge.hpp"
#include "vision/odometry_sequences.hpp"

namespace hanzo::fusion::pipeline {
namespace {

struct CameraSession {
  msgs::FusionMap map;
  std::vector<Eigen::Vector3d> keyframe_truth;  ///< the camera's true position at each keyframe
};

CameraSession camera_session(const vision::sequences::Sequence& sequence, std::size_t first, std::size_t last, const std::string& name) {
  const cv::Mat image = cv::imread(sequence.images[first], cv::IMREAD_GRAYSCALE);
  auto odometry = vision::VisualOdometry::create(sequence.camera, image.size()).value();
  for (std::size_t i = first; i <= last; ++i) {
    const Result<vision::VisualOdometryFrame> frame = odometry->track(sequence.times[i], cv::imread(sequence.images[i], cv::IMREAD_UNCHANGED));
    EXPECT_TRUE(frame) << frame.error().message;
  }
  CameraSession session;
  session.map.map_id = name;
  session.map.visual_landmarks = odometry->landmark_layer("cam0");
  EXPECT_TRUE(session.map.visual_landmarks->scale_free);
  for (const msgs::VisualKeyframe& keyframe : session.map.visual_landmarks->keyframes) {
    for (std::size_t i = 0; i < sequence.ground_truth.size(); ++i) {
      if (std::abs((sequence.ground_truth.timestamps[i] - keyframe.time).seconds()) < 1e-3) {
        session.keyframe_truth.push_back(sequence.ground_truth.poses[i].block<3, 1>(0, 3));
      }
    }
  }
  EXPECT_EQ(session.keyframe_truth.size(), session.map.visual_landmarks->keyframes.size());
  return session;
}

/// Mean and largest distance of the keyframes from the truth after one similarity (m).
std::pair<double, double> keyframe_errors(const std::vector<Eigen::Vector3d>& estimate, const std::vector<Eigen::Vector3d>& truth) {
  const eval::SimilarityTransform alignment = eval::umeyama_alignment(estimate, truth, true).value();
  double worst = 0.0, sum = 0.0;
  for (std::size_t k = 0; k < estimate.size(); ++k) {
    const double error = (alignment.scale * (alignment.rotation * estimate[k]) + alignment.translation - truth[k]).norm();
    worst = std::max(worst, error);
    sum += error;
  }
  return {sum / static_cast<double>(estimate.size()), worst};
}

std::vector<Eigen::Vector3d> positions(const msgs::VisualLandmarkLayer& layer) {
  std::vector<Eigen::Vector3d> out;
  for (const msgs::VisualKeyframe& keyframe : layer.keyframes) out.push_back(keyframe.T_world_camera.position);
  return out;
}

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
  const CameraSession a = camera_session(street, 0, 32, "first");
  const CameraSession b = camera_session(street, 18, 50, "second");
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
  const auto [mean, worst] = keyframe_errors(positions(layer), truth);
  const auto [mean_a, worst_a] = keyframe_errors(positions(*a.map.visual_landmarks), a.keyframe_truth);
  const auto [mean_b, worst_b] = keyframe_errors(positions(*b.map.visual_landmarks), b.keyframe_truth);
  std::printf("%zu keyframes over 60 m: mean %.3f m, max %.3f m from the truth (each session alone over 38 m: mean %.3f / %.3f, max %.3f / %.3f)\n",
              truth.size(), mean, worst, mean_a, mean_b, worst_a, worst_b);
  EXPECT_LT(worst, 0.5);

  // The same second session in another frame at 2.5 times its scale joins at 2.5 times the scale.
  const SE3 elsewhere(SO3::from_axis_angle(Eigen::Vector3d(0.3, -1.0, 0.2).normalized(), 2.0), Eigen::Vector3d(40.0, -7.0, 3.0));
  const Result<SessionMergeResult> rescaled = merge_sessions({a.map, moved(b.map, 2.5, elsewhere)});
  ASSERT_TRUE(rescaled) << rescaled.error().message;
  EXPECT_NEAR(rescaled->joins[0].scale, merged->joins[0].scale / 2.5, 0.02 * merged->joins[0].scale / 2.5);
  EXPECT_LT(keyframe_errors(positions(*rescaled->merged.visual_landmarks), truth).second, 0.5);

  const msgs::FusionMap reread = maps::parse_fusion_map(maps::serialize_fusion_map(merged->merged, {.chunk_bytes = 1 << 16}).value()).value();
  ASSERT_TRUE(reread.visual_landmarks);
  EXPECT_EQ(reread.visual_landmarks->sources, layer.sources);
  EXPECT_TRUE(reread.visual_landmarks->scale_free);
  EXPECT_EQ(reread.visual_landmarks->keyframes.back().source, 1U);

  const CameraSession other = camera_session(vision::sequences::kitti_raw_0052(), 0, 30, "other");
  const Result<SessionMergeResult> refused = merge_sessions({a.map, other.map});
  ASSERT_FALSE(refused) << "joined another street";
  std::printf("another street: %s\n", refused.error().message.c_str());
  EXPECT_NE(refused.error().message.find("other not joined to first"), std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
