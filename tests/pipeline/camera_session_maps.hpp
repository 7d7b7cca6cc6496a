#pragma once
// Camera sessions' landmark maps from real image sequences (tests/vision/odometry_sequences.hpp)
// for the session-merge tests: the visual odometry over a range of frames, its landmark layer as
// a FusionMap, the true camera position at each keyframe, and keyframe errors after one
// similarity (as monocular maps need).

#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/eval/alignment.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "vision/odometry_sequences.hpp"

namespace hanzo::fusion::testing {

struct CameraSessionMap {
  msgs::FusionMap map;
  std::vector<Eigen::Vector3d> keyframe_truth;  ///< the camera's true position at each keyframe
};

/// Frames [first, last] of `sequence` through the visual odometry; the map is named `name`.
inline CameraSessionMap camera_session_map(const vision::sequences::Sequence& sequence, std::size_t first, std::size_t last, const std::string& name,
                                           const vision::VisualOdometryConfig& config = {}) {
  const cv::Mat image = cv::imread(sequence.images[first], cv::IMREAD_GRAYSCALE);
  auto odometry = vision::VisualOdometry::create(sequence.camera, image.size(), config).value();
  for (std::size_t i = first; i <= last; ++i) {
    const Result<vision::VisualOdometryFrame> frame = odometry->track(sequence.times[i], cv::imread(sequence.images[i], cv::IMREAD_UNCHANGED));
    EXPECT_TRUE(frame) << frame.error().message;
  }
  CameraSessionMap session;
  session.map.map_id = name;
  session.map.visual_landmarks = odometry->landmark_layer("cam0");
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

inline std::vector<Eigen::Vector3d> keyframe_positions(const msgs::VisualLandmarkLayer& layer) {
  std::vector<Eigen::Vector3d> out;
  for (const msgs::VisualKeyframe& keyframe : layer.keyframes) out.push_back(keyframe.T_world_camera.position);
  return out;
}

/// Mean and largest distance of the keyframes from the truth after one similarity (m).
inline std::pair<double, double> keyframe_errors(const std::vector<Eigen::Vector3d>& estimate, const std::vector<Eigen::Vector3d>& truth) {
  const eval::SimilarityTransform alignment = eval::umeyama_alignment(estimate, truth, true).value();
  double worst = 0.0, sum = 0.0;
  for (std::size_t k = 0; k < estimate.size(); ++k) {
    const double error = (alignment.scale * (alignment.rotation * estimate[k]) + alignment.translation - truth[k]).norm();
    worst = std::max(worst, error);
    sum += error;
  }
  return {sum / static_cast<double>(estimate.size()), worst};
}

}  // namespace hanzo::fusion::testing
