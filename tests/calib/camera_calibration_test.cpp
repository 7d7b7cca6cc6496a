// Camera intrinsic calibration: views of a checkerboard rendered by the simulator through known
// lenses (radtan, equidistant) give back the intrinsics and a lens that maps the image the same
// way; bad input is refused by name.

#include "hanzo/fusion/calib/camera_calibration.hpp"

#include <cmath>
#include <random>
#include <string>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "support/checkerboard_views.hpp"

namespace hanzo::fusion::calib {
namespace {

using ::testing::HasSubstr;

using test_support::kCornersX;
using test_support::kCornersY;
using test_support::kSquare;
using test_support::lens;
using test_support::render_views;

// The largest distance between where the true and the calibrated lens put the same rays, over
// a grid of pixels of the true image's central 60 % x 60 % (where the views put the board; the
// coefficients themselves trade off against each other, and nothing pins the lens beyond).
double largest_mapping_difference(const sim::CameraSimulatorConfig& truth, const CameraCalibrationResult& calibrated) {
  const msgs::CameraIntrinsics& k = truth.intrinsics;
  const cv::Matx33d true_matrix(k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1);
  const msgs::CameraIntrinsics& c = calibrated.intrinsics;
  const cv::Matx33d calibrated_matrix(c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1);
  const bool fisheye = truth.distortion.type == msgs::DistortionType::kEquidistant;
  std::vector<cv::Point2d> pixels;
  for (double u = 0.2; u < 0.81; u += 0.05) {
    for (double v = 0.2; v < 0.81; v += 0.05) pixels.emplace_back(u * k.width, v * k.height);
  }
  std::vector<cv::Point2d> normalized;
  if (fisheye) {
    cv::fisheye::undistortPoints(pixels, normalized, true_matrix, truth.distortion.coefficients);
  } else {
    cv::undistortPoints(pixels, normalized, true_matrix, truth.distortion.coefficients);
  }
  std::vector<cv::Point3d> rays;
  for (const cv::Point2d& n : normalized) rays.emplace_back(n.x, n.y, 1.0);
  std::vector<cv::Point2d> again;
  if (fisheye) {
    cv::fisheye::projectPoints(rays, again, cv::Vec3d::all(0), cv::Vec3d::all(0), calibrated_matrix, calibrated.distortion.coefficients);
  } else {
    cv::projectPoints(rays, cv::Vec3d::all(0), cv::Vec3d::all(0), calibrated_matrix, calibrated.distortion.coefficients, again);
  }
  double largest = 0.0;
  for (std::size_t i = 0; i < pixels.size(); ++i) largest = std::max(largest, std::hypot(again[i].x - pixels[i].x, again[i].y - pixels[i].y));
  return largest;
}

std::string describe(const CameraCalibrationResult& result) {
  return fmt::format("fx {:.2f} fy {:.2f} cx {:.2f} cy {:.2f} distortion [{}] RMS {:.3f} px", result.intrinsics.fx, result.intrinsics.fy,
                     result.intrinsics.cx, result.intrinsics.cy, fmt::join(result.distortion.coefficients, ", "), result.rms_px);
}

CameraCalibrationConfig board_config(msgs::DistortionType model) {
  CameraCalibrationConfig config;
  config.target = {kCornersX, kCornersY, kSquare};
  config.model = model;
  return config;
}

TEST(CameraCalibration, RecoversARadtanLensFromRenderedBoardViews) {
  const sim::CameraSimulatorConfig truth =
      lens({458.654, 457.296, 367.215, 248.375, 752, 480}, {msgs::DistortionType::kRadtan, {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05}});
  const std::vector<msgs::ImageMessage> images = render_views(truth, 16, {0.2, 0.12});
  auto calibrated = calibrate_camera(images, board_config(msgs::DistortionType::kRadtan));
  ASSERT_TRUE(calibrated.ok()) << calibrated.error().message;
  EXPECT_GE(calibrated->views_found, 10U);
  EXPECT_EQ(calibrated->views_used, calibrated->views_found);
  EXPECT_LT(calibrated->rms_px, 0.15);
  EXPECT_NEAR(calibrated->intrinsics.fx, truth.intrinsics.fx, 2.0);
  EXPECT_NEAR(calibrated->intrinsics.fy, truth.intrinsics.fy, 2.0);
  EXPECT_NEAR(calibrated->intrinsics.cx, truth.intrinsics.cx, 2.0);
  EXPECT_NEAR(calibrated->intrinsics.cy, truth.intrinsics.cy, 2.0);
  EXPECT_EQ(calibrated->intrinsics.width, 752U);
  ASSERT_TRUE(calibrated->intrinsics_std.has_value());
  EXPECT_LT((*calibrated->intrinsics_std)[0], 1.0);
  ASSERT_EQ(calibrated->distortion.coefficients.size(), 4U);
  EXPECT_NEAR(calibrated->distortion.coefficients[0], -0.2834, 0.02);
  // Measured: fx, fy 0.2 % low, cx, cy within 0.4 px, k1 -0.2821 (truth -0.2834); 0.91 px at
  // the edge of the central region, where k1 and k2 trade off against the focal length.
  EXPECT_LT(largest_mapping_difference(truth, *calibrated), 1.2) << describe(*calibrated);
  // Each used view's board pose: in front of the camera, 0.7-1.1 m away.
  for (const CameraCalibrationView& view : calibrated->views) {
    if (!view.used) continue;
    EXPECT_GT(view.T_camera_target.translation().z(), 0.5);
    EXPECT_LT(view.T_camera_target.translation().norm(), 1.4);
  }
}

TEST(CameraCalibration, RecoversAnEquidistantLens) {
  const sim::CameraSimulatorConfig truth =
      lens({280.0, 280.0, 319.5, 239.5, 640, 480}, {msgs::DistortionType::kEquidistant, {0.0034823894, 0.000715034, -0.0020532361, 0.0002029532}});
  const std::vector<msgs::ImageMessage> images = render_views(truth, 16, {0.5, 0.35});
  auto calibrated = calibrate_camera(images, board_config(msgs::DistortionType::kEquidistant));
  ASSERT_TRUE(calibrated.ok()) << calibrated.error().message;
  EXPECT_GE(calibrated->views_used, 10U);
  EXPECT_LT(calibrated->rms_px, 0.15);
  EXPECT_NEAR(calibrated->intrinsics.fx, 280.0, 1.5);
  EXPECT_NEAR(calibrated->intrinsics.fy, 280.0, 1.5);
  EXPECT_NEAR(calibrated->intrinsics.cx, 319.5, 1.5);
  EXPECT_NEAR(calibrated->intrinsics.cy, 239.5, 1.5);
  EXPECT_EQ(calibrated->distortion.type, msgs::DistortionType::kEquidistant);
  EXPECT_LT(largest_mapping_difference(truth, *calibrated), 1.2) << describe(*calibrated);  // measured 0.74 px
}

TEST(CameraCalibration, RefusesWhatCannotCalibrateByName) {
  const sim::CameraSimulatorConfig truth = lens({400.0, 400.0, 319.5, 239.5, 640, 480}, {});
  std::vector<msgs::ImageMessage> images = render_views(truth, 3, {0.1, 0.1});
  const CameraCalibrationConfig config = board_config(msgs::DistortionType::kRadtan);

  auto too_few = calibrate_camera(images, config);
  ASSERT_FALSE(too_few.ok());
  EXPECT_EQ(too_few.error().field, "images");
  EXPECT_THAT(too_few.error().message, HasSubstr("found in 3 of 3 images; 6 views are needed"));

  CameraCalibrationConfig wrong_board = config;
  wrong_board.target.inner_corners_x = 7;  // not the board in view
  EXPECT_THAT(calibrate_camera(images, wrong_board).error().message, HasSubstr("found in 0 of 3"));

  std::vector<msgs::ImageMessage> mixed = images;
  mixed[1].width = 320;
  EXPECT_EQ(calibrate_camera(mixed, config).error().field, "images[1]");
  std::vector<msgs::ImageMessage> depth = images;
  depth[2].encoding = msgs::ImageEncoding::kDepth16;
  EXPECT_THAT(calibrate_camera(depth, config).error().message, HasSubstr("not an intensity image"));
  EXPECT_EQ(calibrate_camera({}, config).error().field, "images");

  CameraCalibrationConfig bad = config;
  bad.target.square_size = 0.0;
  EXPECT_EQ(calibrate_camera(images, bad).error().field, "target.square_size");
  bad = config;
  bad.model = msgs::DistortionType::kNone;
  EXPECT_EQ(calibrate_camera(images, bad).error().field, "model");
}

}  // namespace
}  // namespace hanzo::fusion::calib
