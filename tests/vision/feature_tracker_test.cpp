// FeatureTracker: tracks follow a known image motion to a fraction of a pixel and keep their ids,
// stereo matches lie on the rig's epipolar lines, bad images are refused.

#include "hanzo/fusion/vision/feature_tracker.hpp"

#include <map>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::vision {
namespace {

cv::Mat euroc_image() {
  return cv::imread(std::string(HANZO_DATA_DIR) + "/euroc_v101_micro/mav0/cam0/data/1403715273262142976.png", cv::IMREAD_GRAYSCALE);
}

cv::Mat shifted(const cv::Mat& image, double dx, double dy) {
  cv::Mat moved;
  const cv::Mat transform = (cv::Mat_<double>(2, 3) << 1, 0, dx, 0, 1, dy);
  cv::warpAffine(image, moved, transform, image.size(), cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  return moved;
}

PinholeCamera ideal_camera() {
  PinholeCamera camera;
  camera.fx = camera.fy = 458.0;
  camera.cx = 376.0;
  camera.cy = 240.0;
  return camera;
}

std::map<uint64_t, Eigen::Vector2d> by_id(const TrackedFrame& frame, int camera) {
  std::map<uint64_t, Eigen::Vector2d> out;
  for (const FeatureObservation& observation : frame.observations) {
    if (observation.camera == camera) out[observation.feature_id] = observation.normalized;
  }
  return out;
}

TEST(FeatureTracker, TracksFollowAKnownShiftAndKeepTheirIds) {
  const cv::Mat image = euroc_image();
  ASSERT_FALSE(image.empty());
  auto tracker = FeatureTracker::create(ideal_camera(), image.size());
  ASSERT_TRUE(tracker) << tracker.error().message;
  const auto first = (*tracker)->track(image);
  ASSERT_TRUE(first);
  EXPECT_EQ(first->new_features, 200);
  EXPECT_EQ(first->tracked, 0);
  const auto second = (*tracker)->track(shifted(image, 6.5, -3.25));
  ASSERT_TRUE(second);
  EXPECT_GT(second->tracked, 170);
  const auto before = by_id(*first, 0), after = by_id(*second, 0);
  int compared = 0, within = 0;
  for (const auto& [id, normalized] : after) {
    const auto found = before.find(id);
    if (found == before.end()) continue;
    ++compared;
    const Eigen::Vector2d motion_px = 458.0 * (normalized - found->second);
    if ((motion_px - Eigen::Vector2d(6.5, -3.25)).norm() < 0.2) ++within;
  }
  EXPECT_EQ(compared, second->tracked);
  EXPECT_GT(within, 0.95 * compared);
  // Ids continue, new features get new ones, and the image stays topped up.
  EXPECT_EQ(second->tracked + second->new_features, static_cast<int>(after.size()));
  EXPECT_LE(static_cast<int>(after.size()), 200);
}

TEST(FeatureTracker, StereoMatchesLieOnTheRigsEpipolarLines) {
  const cv::Mat image = euroc_image();
  // A rectified rig 11 cm wide seeing a plane 3 m away: the right image is the left shifted by
  // the disparity f b / Z = 458 * 0.11 / 3 = 16.8 px.
  const double disparity = 458.0 * 0.11 / 3.0;
  auto tracker = FeatureTracker::create_stereo(ideal_camera(), ideal_camera(), SE3(SO3(), Eigen::Vector3d(0.11, 0, 0)), image.size());
  ASSERT_TRUE(tracker) << tracker.error().message;
  const auto frame = (*tracker)->track(image, shifted(image, -disparity, 0.0));
  ASSERT_TRUE(frame);
  EXPECT_GT(frame->stereo_matches, 150);
  const auto left = by_id(*frame, 0), right = by_id(*frame, 1);
  ASSERT_EQ(static_cast<int>(right.size()), frame->stereo_matches);
  for (const auto& [id, normalized] : right) {
    const Eigen::Vector2d offset_px = 458.0 * (normalized - left.at(id));
    EXPECT_NEAR(offset_px.y(), 0.0, 0.3);
    EXPECT_NEAR(offset_px.x(), -disparity, 0.3);
  }
}

TEST(FeatureTracker, RefusesBadImagesAndKeepsItsTracks) {
  const cv::Mat image = euroc_image();
  EXPECT_FALSE(FeatureTracker::create(ideal_camera(), cv::Size(16, 16)));
  FeatureTrackerConfig bad;
  bad.window_px = 20;
  const auto refused = FeatureTracker::create(ideal_camera(), image.size(), bad);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("window_px"), std::string::npos);
  EXPECT_FALSE(FeatureTracker::create_stereo(ideal_camera(), ideal_camera(), SE3(), image.size()));

  auto tracker = FeatureTracker::create(ideal_camera(), image.size());
  ASSERT_TRUE(tracker);
  ASSERT_TRUE((*tracker)->track(image));
  EXPECT_FALSE((*tracker)->track(cv::Mat()));
  EXPECT_FALSE((*tracker)->track(cv::Mat(100, 100, CV_8UC1, cv::Scalar(0))));
  EXPECT_FALSE((*tracker)->track(cv::Mat(image.size(), CV_32FC1, cv::Scalar(0))));
  EXPECT_FALSE((*tracker)->track(image, image));  // a pair given to a monocular tracker
  const auto next = (*tracker)->track(shifted(image, 2.0, 1.0));
  ASSERT_TRUE(next);
  EXPECT_GT(next->tracked, 170);
}

// A static mask (a detector's moving object): tracks that land on it end and no feature starts
// there; a mask of the wrong size is refused.
TEST(FeatureTracker, NoFeatureIsTrackedOrStartedOnAMovingObject) {
  const cv::Mat image = euroc_image();
  ASSERT_FALSE(image.empty());
  auto tracker = FeatureTracker::create(ideal_camera(), image.size());
  ASSERT_TRUE(tracker);
  const auto first = (*tracker)->track(image);
  ASSERT_TRUE(first);
  StaticMask mask{cv::Mat(image.size(), CV_8UC1, cv::Scalar(255))};
  const cv::Rect object(0, 0, image.cols / 2, image.rows);  // the left half
  mask.pixels(object).setTo(0);
  const auto second = (*tracker)->track(shifted(image, 2.0, 1.0), mask);
  ASSERT_TRUE(second);
  EXPECT_GT(second->masked, 50);
  EXPECT_GT(second->tracked, 50);
  for (const FeatureObservation& observation : second->observations) {
    const double u = 376.0 + 458.0 * observation.normalized.x();
    EXPECT_GE(u, image.cols / 2 - 0.5) << observation.feature_id;
  }
  EXPECT_FALSE((*tracker)->track(image, StaticMask{cv::Mat(10, 10, CV_8UC1, cv::Scalar(255))}));
}

}  // namespace
}  // namespace hanzo::fusion::vision
