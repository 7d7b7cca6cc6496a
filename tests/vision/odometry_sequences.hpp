#pragma once
// Image sequences with ground truth for the visual odometry tests, and a run over one:
// KITTI odometry 06 (frames 0-50, 60 m straight; ../shared/data/kitti_odometry_06_first51) and
// KITTI raw 0052 (../shared/data/kitti_raw_0052).

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/vision/visual_odometry.hpp"

namespace hanzo::fusion::vision::sequences {

// HANZO_TEST_VERBOSE=1: every frame's state and the errors along the way.
inline bool verbose() {
  static const bool enabled = [] {
    if (std::getenv("HANZO_TEST_VERBOSE") == nullptr) return false;
    auto stderr_logger = std::make_shared<spdlog::logger>("test", std::make_shared<spdlog::sinks::stderr_sink_mt>());
    stderr_logger->set_level(spdlog::level::debug);
    set_logger(stderr_logger);
    return true;
  }();
  return enabled;
}

struct Sequence {
  std::vector<std::string> images;
  std::vector<double> times;
  PinholeCamera camera;
  io::Trajectory ground_truth;
};

inline Sequence kitti_odometry_06() {
  const std::string folder = std::string(HANZO_DATA_DIR) + "/kitti_odometry_06_first51";
  Sequence sequence;
  std::ifstream times(folder + "/times_from_pyslam_kitti06.txt");
  double time = 0.0;
  while (times >> time && sequence.times.size() < 51) sequence.times.push_back(time);
  for (int i = 0; i < 51; ++i) sequence.images.push_back(fmt::format("{}/image_l/{:06d}.png", folder, i));
  sequence.camera.fx = sequence.camera.fy = 707.0912;
  sequence.camera.cx = 601.8873;
  sequence.camera.cy = 183.1104;
  sequence.ground_truth = io::read_trajectory(folder + "/gt_cam0.tum", io::TrajectoryFormat::kTum).value();
  return sequence;
}

// KITTI raw 2011_09_26_drive_0052 (78 frames: 8 m driving, then standing beside moving trucks;
// ../shared/data/kitti_raw_0052). Unix times (the ground truth's clock), colour images (converted to grey by the extractor).
inline Sequence kitti_raw_0052() {
  const std::string folder = std::string(HANZO_DATA_DIR) + "/kitti_raw_0052";
  Sequence sequence;
  std::ifstream times(folder + "/times.txt");
  std::string index;
  double unix_time = 0.0, since_start = 0.0;
  while (times >> index >> unix_time >> since_start) {
    sequence.times.push_back(unix_time);
    sequence.images.push_back(fmt::format("{}/image_02/{}.png", folder, index));
  }
  sequence.camera.fx = sequence.camera.fy = 721.5377;
  sequence.camera.cx = 609.5593;
  sequence.camera.cy = 172.854;
  sequence.ground_truth = io::read_trajectory(folder + "/gt_cam2.tum", io::TrajectoryFormat::kTum).value();
  return sequence;
}

struct RunResult {
  io::Trajectory estimate;
  VisualOdometrySummary summary;
};

// `mask_of`: where each image's features may be taken (a detector's static mask); none: anywhere.
inline RunResult run(const Sequence& sequence, const VisualOdometryConfig& config = {},
                     const std::function<StaticMask(const cv::Mat&)>& mask_of = {}) {
  const cv::Mat first = cv::imread(sequence.images.front(), cv::IMREAD_GRAYSCALE);
  auto odometry = VisualOdometry::create(sequence.camera, first.size(), config).value();
  for (std::size_t i = 0; i < sequence.images.size(); ++i) {
    const cv::Mat image = cv::imread(sequence.images[i], cv::IMREAD_UNCHANGED);
    const Result<VisualOdometryFrame> frame = odometry->track(sequence.times[i], image, mask_of ? mask_of(image) : StaticMask{});
    EXPECT_TRUE(frame) << frame.error().message;
    if (frame && verbose()) {
      std::printf("%3zu %-12s %4d %s%s %s\n", i, to_string(frame->state), frame->tracked_landmarks, frame->keyframe ? "KF" : "  ",
                  frame->standing_still ? " still" : "", frame->reason.c_str());
    }
  }
  RunResult result;
  for (const auto& [time, pose] : odometry->trajectory()) {
    result.estimate.timestamps.push_back(Timestamp::from_seconds(time));
    result.estimate.poses.push_back(pose.matrix());
  }
  result.summary = odometry->summary();
  return result;
}

// The ground-truth poses at the estimate's times (same clock, exact times).
inline io::Trajectory at_times(const io::Trajectory& reference, const io::Trajectory& estimate) {
  std::vector<std::size_t> indices;
  for (const Timestamp& time : estimate.timestamps) {
    for (std::size_t i = 0; i < reference.size(); ++i) {
      if (std::abs((reference.timestamps[i] - time).seconds()) < 1e-3) {
        indices.push_back(i);
        break;
      }
    }
  }
  return reference.subset(indices);
}

}  // namespace hanzo::fusion::vision::sequences
