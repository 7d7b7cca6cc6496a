#include "hanzo/fusion/calib/camera_calibration.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "checkerboard_corners.hpp"
#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::calib {
namespace {

struct Detection {
  std::size_t image = 0;  // index into the images
  std::vector<cv::Point2f> corners;
};

struct Solution {
  cv::Matx33d camera_matrix;
  cv::Mat distortion;
  std::vector<cv::Vec3d> rotations, translations;
  std::vector<double> view_rms;
  double rms = 0.0;
  std::optional<std::vector<double>> intrinsics_std;
};

Result<Solution> solve(const std::vector<std::vector<cv::Point3f>>& object, const std::vector<std::vector<cv::Point2f>>& image,
                       const cv::Size& size, const CameraCalibrationConfig& config) {
  Solution solution;
  try {
    if (config.model == msgs::DistortionType::kEquidistant) {
      cv::Mat distortion = cv::Mat::zeros(4, 1, CV_64F);
      cv::Mat K = cv::Mat::eye(3, 3, CV_64F);
      std::vector<cv::Mat> rotations, translations;
      cv::fisheye::calibrate(object, image, size, K, distortion, rotations, translations,
                             cv::fisheye::CALIB_RECOMPUTE_EXTRINSIC | cv::fisheye::CALIB_FIX_SKEW,
                             cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-10));
      solution.camera_matrix = cv::Matx33d(K);
      solution.distortion = distortion;
      for (std::size_t v = 0; v < rotations.size(); ++v) {
        solution.rotations.emplace_back(rotations[v]);
        solution.translations.emplace_back(translations[v]);
      }
    } else {
      cv::Mat K, distortion, std_intrinsics, std_extrinsics, view_errors;
      std::vector<cv::Mat> rotations, translations;
      const int flags = config.estimate_k3 ? 0 : cv::CALIB_FIX_K3;
      cv::calibrateCamera(object, image, size, K, distortion, rotations, translations, std_intrinsics, std_extrinsics, view_errors, flags,
                          cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-10));
      solution.camera_matrix = cv::Matx33d(K);
      solution.distortion = distortion.reshape(1, static_cast<int>(distortion.total())).rowRange(0, config.estimate_k3 ? 5 : 4).clone();
      solution.intrinsics_std = std::vector<double>{std_intrinsics.at<double>(0), std_intrinsics.at<double>(1), std_intrinsics.at<double>(2),
                                                    std_intrinsics.at<double>(3)};
      for (std::size_t v = 0; v < rotations.size(); ++v) {
        solution.rotations.emplace_back(rotations[v]);
        solution.translations.emplace_back(translations[v]);
      }
    }
  } catch (const cv::Exception& error) {
    return Error(fmt::format("the calibration did not converge: {}", error.err));
  }
  // Per-view and overall reprojection RMS, the same way for both models.
  double squared = 0.0;
  std::size_t count = 0;
  for (std::size_t v = 0; v < object.size(); ++v) {
    std::vector<cv::Point2f> projected;
    if (config.model == msgs::DistortionType::kEquidistant) {
      cv::fisheye::projectPoints(object[v], projected, solution.rotations[v], solution.translations[v], solution.camera_matrix,
                                 solution.distortion);
    } else {
      cv::projectPoints(object[v], solution.rotations[v], solution.translations[v], solution.camera_matrix, solution.distortion, projected);
    }
    double view_squared = 0.0;
    for (std::size_t i = 0; i < projected.size(); ++i) {
      const cv::Point2f d = projected[i] - image[v][i];
      view_squared += d.dot(d);
    }
    solution.view_rms.push_back(std::sqrt(view_squared / static_cast<double>(projected.size())));
    squared += view_squared;
    count += projected.size();
  }
  solution.rms = std::sqrt(squared / static_cast<double>(count));
  if (!std::isfinite(solution.rms) || !(solution.camera_matrix(0, 0) > 0) || !(solution.camera_matrix(1, 1) > 0)) {
    return Error(fmt::format("the calibration did not converge (RMS {} px, fx {})", solution.rms, solution.camera_matrix(0, 0)));
  }
  return solution;
}

}  // namespace

Status CameraCalibrationConfig::validate() const {
  if (target.inner_corners_x < 2 || target.inner_corners_y < 2) {
    return Error(fmt::format("target: a board needs at least 2 x 2 inner corners, got {} x {}", target.inner_corners_x,
                             target.inner_corners_y),
                 "target");
  }
  if (!(target.square_size > 0) || !std::isfinite(target.square_size)) {
    return Error(fmt::format("target.square_size: {} m is not > 0", target.square_size), "target.square_size");
  }
  if (model != msgs::DistortionType::kRadtan && model != msgs::DistortionType::kEquidistant) {
    return Error(fmt::format("model: {} cannot be calibrated (radtan or equidistant)", msgs::to_string(model)), "model");
  }
  if (min_views < 3) return Error(fmt::format("min_views: {} is below 3", min_views), "min_views");
  if (max_views < min_views) return Error(fmt::format("max_views: {} is below min_views {}", max_views, min_views), "max_views");
  if (!(max_view_rms_px > 0) || !(outlier_factor >= 1)) return Error("max_view_rms_px must be > 0 and outlier_factor >= 1", "max_view_rms_px");
  return ok_status();
}

Result<CameraCalibrationResult> calibrate_camera(const std::vector<msgs::ImageMessage>& images, const CameraCalibrationConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  if (images.empty()) return Error("images: none given", "images");
  const cv::Size size(static_cast<int>(images.front().width), static_cast<int>(images.front().height));
  const cv::Size pattern(config.target.inner_corners_x, config.target.inner_corners_y);
  CameraCalibrationResult result;
  result.views_total = images.size();
  std::vector<Detection> detections;
  for (std::size_t i = 0; i < images.size(); ++i) {
    const msgs::ImageMessage& image = images[i];
    if (static_cast<int>(image.width) != size.width || static_cast<int>(image.height) != size.height) {
      return Error(fmt::format("images[{}]: {} x {} px, but images[0] is {} x {}", i, image.width, image.height, size.width, size.height),
                   fmt::format("images[{}]", i));
    }
    cv::Mat grey;
    HANZO_ASSIGN_OR_RETURN(grey, grey_of(image, i));
    CameraCalibrationView& view = result.views.emplace_back();
    view.time = image.timestamp;
    std::vector<cv::Point2f> corners;
    view.board_found = find_checkerboard_corners(grey, config.target, &corners);
    if (!view.board_found) continue;
    for (const cv::Point2f& corner : corners) view.corners.emplace_back(corner.x, corner.y);
    detections.push_back({i, std::move(corners)});
  }
  result.views_found = detections.size();
  if (detections.size() < config.min_views) {
    return Error(fmt::format("the whole {} x {} board was found in {} of {} images; {} views are needed (the board must be entirely "
                             "in view, with a light border around it)",
                             pattern.width, pattern.height, detections.size(), images.size(), config.min_views),
                 "images");
  }
  // Evenly spread over the recording when there are more than max_views.
  if (detections.size() > config.max_views) {
    std::vector<Detection> chosen;
    for (std::size_t k = 0; k < config.max_views; ++k) chosen.push_back(std::move(detections[k * detections.size() / config.max_views]));
    detections = std::move(chosen);
  }

  const std::vector<cv::Point3f> points = board_points(config.target);
  Solution solution;
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<std::vector<cv::Point3f>> object(detections.size(), points);
    std::vector<std::vector<cv::Point2f>> corners;
    for (const Detection& detection : detections) corners.push_back(detection.corners);
    HANZO_ASSIGN_OR_RETURN(solution, solve(object, corners, size, config));
    if (pass == 1) break;
    std::vector<double> sorted = solution.view_rms;
    std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
    const double limit = std::max(config.outlier_factor * sorted[sorted.size() / 2], config.max_view_rms_px);
    std::vector<Detection> kept;
    for (std::size_t v = 0; v < detections.size(); ++v) {
      if (solution.view_rms[v] <= limit) kept.push_back(std::move(detections[v]));
    }
    if (kept.size() == detections.size()) break;
    logger()->info("camera calibration: {} of {} views above {:.2f} px dropped", detections.size() - kept.size(), detections.size(), limit);
    if (kept.size() < config.min_views) {
      return Error(fmt::format("only {} views reproject within {:.2f} px; {} are needed", kept.size(), limit, config.min_views), "images");
    }
    detections = std::move(kept);
  }
  for (std::size_t v = 0; v < detections.size(); ++v) {
    CameraCalibrationView& view = result.views[detections[v].image];
    view.used = true;
    view.rms_px = solution.view_rms[v];
    cv::Matx33d rotation;
    cv::Rodrigues(solution.rotations[v], rotation);
    Eigen::Matrix3d R;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) R(r, c) = rotation(r, c);
    }
    const cv::Vec3d& t = solution.translations[v];
    view.T_camera_target = SE3(SO3::from_matrix(R), Eigen::Vector3d(t[0], t[1], t[2]));
  }
  const cv::Matx33d& K = solution.camera_matrix;
  result.intrinsics = {K(0, 0), K(1, 1), K(0, 2), K(1, 2), static_cast<uint32_t>(size.width), static_cast<uint32_t>(size.height)};
  result.distortion.type = config.model;
  for (int i = 0; i < static_cast<int>(solution.distortion.total()); ++i) result.distortion.coefficients.push_back(solution.distortion.at<double>(i));
  result.rms_px = solution.rms;
  result.intrinsics_std = solution.intrinsics_std;
  result.views_used = detections.size();
  return result;
}

}  // namespace hanzo::fusion::calib
