// Stereo calibration on OpenCV's real chessboard pairs (../shared/data/camera_calib_opencv_stereo:
// 13 pairs, 640 x 480, 9 x 6 inner corners, squares of unit size): the left camera's
// intrinsics match OpenCV's own regression test (RMS 0.196 px, K within its tolerance); the
// right camera sits 3.33 squares along the left's x axis with the epipolar error well under a
// pixel, and the jackknife covariance bounds the pose to millimetres of a square; pairs given
// unevenly are refused.
#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/calib/stereo_calibration.hpp"

namespace hanzo::fusion::calib {
namespace {

const std::string kFolder = std::string(HANZO_DATA_DIR) + "/camera_calib_opencv_stereo/";

std::vector<msgs::ImageMessage> images(const std::string& side) {
  std::vector<msgs::ImageMessage> loaded;
  for (const int number : {1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14}) {
    const cv::Mat grey = cv::imread(kFolder + side + fmt::format("{:02}.jpg", number), cv::IMREAD_GRAYSCALE);
    msgs::ImageMessage& image = loaded.emplace_back();
    image.timestamp = Timestamp::from_seconds(number);
    image.width = static_cast<uint32_t>(grey.cols);
    image.height = static_cast<uint32_t>(grey.rows);
    image.encoding = msgs::ImageEncoding::kMono8;
    image.data.assign(grey.datastart, grey.dataend);
  }
  return loaded;
}

TEST(StereoCalibration, OpenCvChessboardPairsGiveTheRigAndTheLeftLensOfOpenCvsRegression) {
  CameraCalibrationConfig config;
  config.target = {9, 6, 1.0};
  config.estimate_k3 = true;  // OpenCV's regression solves k1 k2 p1 p2 k3
  const std::vector<msgs::ImageMessage> left = images("left"), right = images("right");
  ASSERT_EQ(left.front().width, 640U);
  const StereoCalibrationResult stereo = calibrate_stereo(left, right, config).value();
  EXPECT_EQ(stereo.pairs_used, 13U);
  // opencv modules/python/test/test_calibration.py: RMS 0.196334638034 (+-0.01), K L1 tolerance 10.
  EXPECT_NEAR(stereo.left.rms_px, 0.196334638034, 0.01);
  const msgs::CameraIntrinsics& k = stereo.left.intrinsics;
  EXPECT_LT(std::abs(k.fx - 532.80992189) + std::abs(k.fy - 532.93346422) + std::abs(k.cx - 342.4952186) + std::abs(k.cy - 233.8879292), 10.0);
  // The rig: the right camera 3.33 squares to the right (OpenCV's stereo_calib sample, with its
  // looser lens model, finds 3.343), nearly parallel.
  const Eigen::Vector3d t = stereo.T_left_right.translation();
  EXPECT_NEAR(t.norm(), 3.343, 0.05);
  EXPECT_GT(t.x(), 3.2);
  EXPECT_LT(std::abs(t.y()) + std::abs(t.z()), 0.1);
  EXPECT_LT(stereo.T_left_right.rotation().log().norm(), 0.01);
  EXPECT_LT(stereo.rms_px, 0.3);
  EXPECT_LT(stereo.epipolar_error_px, 0.3);
  ASSERT_EQ(stereo.pair_rms_px.size(), 13U);
  // Jackknife: positive, millimetres of a square, and the pose within a few sigma of OpenCV's.
  const Eigen::Matrix<double, 6, 1> sigma = stereo.covariance.diagonal().cwiseSqrt();
  EXPECT_GT(sigma.minCoeff(), 0.0);
  EXPECT_LT(sigma.head<3>().maxCoeff(), 0.02);
  EXPECT_LT(sigma.tail<3>().maxCoeff(), 0.002);
  EXPECT_LT(std::abs(t.norm() - 3.343), 5.0 * sigma(0) + 0.01);

  std::vector<msgs::ImageMessage> fewer = right;
  fewer.pop_back();
  const auto refused = calibrate_stereo(left, fewer, config);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("13 left and 12 right"), std::string::npos) << refused.error().message;
}

}  // namespace
}  // namespace hanzo::fusion::calib
