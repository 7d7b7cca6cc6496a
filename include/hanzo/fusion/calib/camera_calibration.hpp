#pragma once
// Camera intrinsic calibration from views of a checkerboard (spec, "Calibration / Intrinsic
// calibration: focal length, principal point, distortion coefficients, computed from multiple
// views of a calibration pattern").
//
//   calib::CameraCalibrationConfig config;
//   config.target = {9, 6, 0.05};   // inner corners along the rows, along the columns; square (m)
//   auto calibrated = calib::calibrate_camera(images, config);
//   // calibrated->intrinsics, ->distortion, ->rms_px, ->views
//
// Steps: each image (mono8, rgb8 or bgr8) is searched for the board's inner corners (OpenCV
// findChessboardCorners, refined to sub-pixel by cornerSubPix); the views where the whole board
// was found are solved together (Zhang's method as OpenCV's calibrateCamera implements it, or
// cv::fisheye::calibrate for the equidistant model), views whose reprojection RMS is above
// max(outlier_factor x the median, max_view_rms_px) are dropped once and the rest solved again.
//
// Frames and units: pixels with OpenCV's convention (integer coordinates are pixel centres);
// T_camera_target of each view in metres, the camera's optical frame (x right, y down, z
// forward), the target's frame at its first inner corner with z out of the board.
// Fails, naming what is wrong: no images, images of different sizes or of a depth encoding, a
// bad target or config, fewer than min_views views with the whole board (the message gives how
// many were found), or a solve that does not converge.
#include <cstddef>
#include <optional>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::calib {

/// A checkerboard: inner corners (where four squares meet) along a row and along a column, and
/// the edge of a square. Boards with different counts along the two axes have one orientation.
struct CheckerboardTarget {
  int inner_corners_x = 9;
  int inner_corners_y = 6;
  double square_size = 0.05;  ///< m
};

struct CameraCalibrationConfig {
  CheckerboardTarget target;
  /// kRadtan (k1, k2, p1, p2; with estimate_k3 also k3) or kEquidistant (k1..k4).
  msgs::DistortionType model = msgs::DistortionType::kRadtan;
  bool estimate_k3 = false;
  std::size_t min_views = 6;       ///< views with the whole board needed to solve
  std::size_t max_views = 40;      ///< evenly chosen among those found (the solve grows with them)
  double max_view_rms_px = 1.0;    ///< a view above this and above outlier_factor x the median is dropped
  double outlier_factor = 3.0;

  Status validate() const;
};

struct CameraCalibrationView {
  Timestamp time;
  bool board_found = false;
  bool used = false;       ///< in the final solve
  double rms_px = 0.0;     ///< reprojection RMS of its corners (solved views)
  SE3 T_camera_target;     ///< solved views
  /// The board's inner corners (px, sub-pixel), row by row from the target's first corner;
  /// views where the whole board was found.
  std::vector<Eigen::Vector2f> corners;
};

struct CameraCalibrationResult {
  msgs::CameraIntrinsics intrinsics;  ///< fx, fy, cx, cy and the image size
  msgs::DistortionModel distortion;
  double rms_px = 0.0;                ///< reprojection RMS over the corners of the used views
  /// One standard deviation of fx, fy, cx, cy (px), from the solve's covariance (radtan only).
  std::optional<std::vector<double>> intrinsics_std;
  std::size_t views_total = 0, views_found = 0, views_used = 0;
  std::vector<CameraCalibrationView> views;  ///< one per image, in order
};

Result<CameraCalibrationResult> calibrate_camera(const std::vector<msgs::ImageMessage>& images, const CameraCalibrationConfig& config);

}  // namespace hanzo::fusion::calib
