#include "hanzo/fusion/calib/stereo_calibration.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>

namespace hanzo::fusion::calib {

namespace {

struct Pairs {
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> left, right;
};

std::vector<cv::Point2f> points_of(const std::vector<Eigen::Vector2f>& corners) {
  std::vector<cv::Point2f> points;
  for (const Eigen::Vector2f& corner : corners) points.emplace_back(corner.x(), corner.y());
  return points;
}

cv::Mat camera_matrix(const msgs::CameraIntrinsics& k) { return (cv::Mat_<double>(3, 3) << k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1); }

// k1 k2 p1 p2 k3 (k3 = 0 for a four-coefficient lens: the same model; OpenCV writes five back).
cv::Mat distortion_of(const msgs::DistortionModel& distortion) {
  cv::Mat coefficients = cv::Mat::zeros(1, 5, CV_64F);
  for (std::size_t i = 0; i < std::min<std::size_t>(distortion.coefficients.size(), 5); ++i) coefficients.at<double>(static_cast<int>(i)) = distortion.coefficients[i];
  return coefficients;
}

struct Solved {
  SE3 T_left_right;
  double rms = 0.0;
  std::vector<double> pair_rms;
  cv::Mat fundamental;
};

// stereoCalibrate with both cameras' intrinsics fixed: R, T map left-frame points into the right's.
Solved solve(const Pairs& pairs, const StereoCalibrationResult& cameras, const cv::Size& size) {
  cv::Mat R, T, E, F, per_view;
  cv::Mat K_left = camera_matrix(cameras.left.intrinsics), K_right = camera_matrix(cameras.right.intrinsics);
  cv::Mat D_left = distortion_of(cameras.left.distortion), D_right = distortion_of(cameras.right.distortion);
  const double rms = cv::stereoCalibrate(pairs.object, pairs.left, pairs.right, K_left, D_left, K_right, D_right, size, R, T, E, F, per_view,
                                         cv::CALIB_FIX_INTRINSIC,
                                         cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-9));
  Eigen::Matrix3d rotation;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) rotation(r, c) = R.at<double>(r, c);
  }
  const SE3 T_right_left(SO3::from_matrix(rotation), Eigen::Vector3d(T.at<double>(0), T.at<double>(1), T.at<double>(2)));
  Solved solved{T_right_left.inverse(), rms, {}, F};
  for (int v = 0; v < per_view.rows; ++v) solved.pair_rms.push_back(0.5 * (per_view.at<double>(v, 0) + per_view.at<double>(v, 1)));
  return solved;
}

StereoCalibrationResult solve_rig(const Pairs& pairs, const cv::Size& size, StereoCalibrationResult result);

}  // namespace

Result<StereoCalibrationResult> calibrate_stereo(const std::vector<msgs::ImageMessage>& left_images,
                                                 const std::vector<msgs::ImageMessage>& right_images, const CameraCalibrationConfig& config) {
  if (left_images.size() != right_images.size()) {
    return Error(fmt::format("{} left and {} right images: give them in pairs", left_images.size(), right_images.size()), "images");
  }
  if (config.model != msgs::DistortionType::kRadtan) return Error("stereo calibration: radtan distortion only", "model");
  StereoCalibrationResult result;
  HANZO_ASSIGN_OR_RETURN(result.left, with_context(calibrate_camera(left_images, config), "left camera"));
  HANZO_ASSIGN_OR_RETURN(result.right, with_context(calibrate_camera(right_images, config), "right camera"));
  result.pairs_total = left_images.size();
  const cv::Size size(static_cast<int>(result.left.intrinsics.width), static_cast<int>(result.left.intrinsics.height));
  std::vector<cv::Point3f> board;
  for (int y = 0; y < config.target.inner_corners_y; ++y) {
    for (int x = 0; x < config.target.inner_corners_x; ++x) {
      board.emplace_back(static_cast<float>(x * config.target.square_size), static_cast<float>(y * config.target.square_size), 0.0F);
    }
  }
  Pairs pairs;
  for (std::size_t i = 0; i < left_images.size(); ++i) {
    const CameraCalibrationView &left = result.left.views[i], &right = result.right.views[i];
    if (!left.board_found || !right.board_found) continue;
    pairs.object.push_back(board);
    pairs.left.push_back(points_of(left.corners));
    pairs.right.push_back(points_of(right.corners));
  }
  result.pairs_used = pairs.object.size();
  if (result.pairs_used < config.min_views || result.pairs_used < 3) {
    return Error(fmt::format("the whole board was found by both cameras in {} of {} pairs; {} are needed", result.pairs_used,
                             result.pairs_total, std::max<std::size_t>(config.min_views, 3)),
                 "images");
  }
  try {
    return solve_rig(pairs, size, std::move(result));
  } catch (const cv::Exception& error) {  // OpenCV reports a degenerate solve by throwing
    return Error(fmt::format("stereo calibration: OpenCV failed: {}", error.what()), "images");
  }
}

namespace {

// The pose, its jackknife covariance and the epipolar error, both cameras solved.
StereoCalibrationResult solve_rig(const Pairs& pairs, const cv::Size& size, StereoCalibrationResult result) {
  const Solved all = solve(pairs, result, size);
  result.T_left_right = all.T_left_right;
  result.rms_px = all.rms;
  result.pair_rms_px = all.pair_rms;
  // Jackknife: each pair left out once.
  const std::size_t n = pairs.object.size();
  std::vector<Eigen::Matrix<double, 6, 1>> deviations;
  Eigen::Matrix<double, 6, 1> mean = Eigen::Matrix<double, 6, 1>::Zero();
  for (std::size_t j = 0; j < n; ++j) {
    Pairs without;
    for (std::size_t i = 0; i < n; ++i) {
      if (i == j) continue;
      without.object.push_back(pairs.object[i]);
      without.left.push_back(pairs.left[i]);
      without.right.push_back(pairs.right[i]);
    }
    const SE3 delta = all.T_left_right.inverse() * solve(without, result, size).T_left_right;
    Eigen::Matrix<double, 6, 1> xi;
    xi << delta.translation(), delta.rotation().log();
    deviations.push_back(xi);
    mean += xi / static_cast<double>(n);
  }
  for (const Eigen::Matrix<double, 6, 1>& xi : deviations) result.covariance += (xi - mean) * (xi - mean).transpose();
  result.covariance *= static_cast<double>(n - 1) / static_cast<double>(n);
  // Epipolar error of the undistorted corners.
  double sum = 0.0;
  std::size_t count = 0;
  for (std::size_t i = 0; i < n; ++i) {
    std::vector<cv::Point2f> left_undistorted, right_undistorted;
    const cv::Mat K_left = camera_matrix(result.left.intrinsics), K_right = camera_matrix(result.right.intrinsics);
    cv::undistortPoints(pairs.left[i], left_undistorted, K_left, distortion_of(result.left.distortion), cv::noArray(), K_left);
    cv::undistortPoints(pairs.right[i], right_undistorted, K_right, distortion_of(result.right.distortion), cv::noArray(), K_right);
    std::vector<cv::Vec3f> lines;
    cv::computeCorrespondEpilines(left_undistorted, 1, all.fundamental, lines);
    for (std::size_t k = 0; k < lines.size(); ++k) {
      sum += std::abs(lines[k][0] * right_undistorted[k].x + lines[k][1] * right_undistorted[k].y + lines[k][2]);
      ++count;
    }
  }
  result.epipolar_error_px = count > 0 ? sum / static_cast<double>(count) : 0.0;
  return result;
}

}  // namespace

}  // namespace hanzo::fusion::calib
