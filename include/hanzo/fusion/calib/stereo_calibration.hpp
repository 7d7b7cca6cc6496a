#pragma once
// Stereo extrinsic calibration from pairs of views of a checkerboard (spec, "extrinsic
// calibration procedures"): each camera's intrinsics as calibrate_camera finds them, then the
// right camera's pose in the left one's optical frame from every pair where both saw the whole
// board (OpenCV stereoCalibrate with the intrinsics fixed: the pose minimizing both cameras'
// reprojection errors over all pairs).
//
//   calib::CameraCalibrationConfig config;
//   config.target = {9, 6, 0.025};
//   auto stereo = calib::calibrate_stereo(left_images, right_images, config);
//   // stereo->T_left_right, ->covariance, ->rms_px, ->epipolar_error_px
//
// Pairs: left_images[i] with right_images[i]. Covariance of T_left_right over (rho, phi) (right
// perturbation, m and rad): a jackknife over the pairs (each left out once, the pose solved
// again), so it reflects how much the board views disagree, not only the corner noise.
// Epipolar error: the mean distance (px) of the right image's undistorted corners from the
// epipolar lines of the left's.
//
// Frames: optical frames (x right, y down, z forward); T_left_right maps points of the right
// camera's frame into the left's (OpenCV's R, T map the left's into the right's: T_right_left):
// a right camera to the right of the left one has the translation (+baseline, 0, 0).
// Fails, naming what is wrong: different numbers of left and right images, either camera's
// calibration failing (calibrate_camera's messages), fewer than config.min_views pairs with the
// whole board in both, or the equidistant model (radtan only).
#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/calib/camera_calibration.hpp"

namespace hanzo::fusion::calib {

struct StereoCalibrationResult {
  CameraCalibrationResult left, right;
  SE3 T_left_right;
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  double rms_px = 0.0;              ///< stereo reprojection RMS over both cameras' corners
  std::vector<double> pair_rms_px;  ///< per pair used (left, right averaged)
  double epipolar_error_px = 0.0;
  std::size_t pairs_total = 0, pairs_used = 0;
};

Result<StereoCalibrationResult> calibrate_stereo(const std::vector<msgs::ImageMessage>& left_images,
                                                 const std::vector<msgs::ImageMessage>& right_images, const CameraCalibrationConfig& config);

}  // namespace hanzo::fusion::calib
