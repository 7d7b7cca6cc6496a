#include "hanzo/fusion/vision/feature_tracker.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <optional>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::vision {
namespace {

bool positive(double value) { return std::isfinite(value) && value > 0.0; }

Result<cv::Mat> to_grey(const cv::Mat& image, cv::Size expected, const char* which) {
  if (image.empty()) return Error(fmt::format("FeatureTracker: the {} image is empty", which), "image");
  if (image.size() != expected)
    return Error(fmt::format("FeatureTracker: the {} image is {}x{}; the tracker was made for {}x{}", which, image.cols, image.rows,
                             expected.width, expected.height), "image");
  if (image.type() == CV_8UC1) return image;
  cv::Mat grey;
  if (image.type() == CV_8UC3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else if (image.type() == CV_8UC4) {
    cv::cvtColor(image, grey, cv::COLOR_BGRA2GRAY);
  } else {
    return Error(fmt::format("FeatureTracker: the {} image has OpenCV type {}; 8-bit grey, BGR or BGRA expected", which, image.type()),
                 "image");
  }
  return grey;
}

bool inside(const cv::Point2f& point, cv::Size size) {
  return point.x >= 1.0f && point.y >= 1.0f && point.x < static_cast<float>(size.width) - 1.0f && point.y < static_cast<float>(size.height) - 1.0f;
}

std::optional<Eigen::Vector2d> normalized(const PinholeCamera& camera, const cv::Point2f& pixel) {
  return camera.unproject(Eigen::Vector2d(pixel.x, pixel.y));
}

}  // namespace

Status validate(const FeatureTrackerConfig& config) {
  if (config.max_features < 8) return Error("FeatureTrackerConfig.max_features: must be at least 8", "max_features");
  if (!positive(config.min_distance_px)) return Error("FeatureTrackerConfig.min_distance_px: must be positive", "min_distance_px");
  if (!(config.quality_level > 0.0 && config.quality_level < 1.0)) return Error("FeatureTrackerConfig.quality_level: must be in (0, 1)", "quality_level");
  if (!(config.min_image_quality >= 0.0 && config.min_image_quality < 1.0)) return Error("FeatureTrackerConfig.min_image_quality: must be in [0, 1)", "min_image_quality");
  if (config.grid_columns < 1 || config.grid_rows < 1 || config.grid_columns * config.grid_rows > config.max_features)
    return Error("FeatureTrackerConfig.grid_columns, grid_rows: at least 1 each and at most max_features cells", "grid_columns");
  if (config.window_px < 5 || config.window_px % 2 == 0) return Error("FeatureTrackerConfig.window_px: must be odd and at least 5", "window_px");
  if (config.pyramid_levels < 0 || config.pyramid_levels > 8) return Error("FeatureTrackerConfig.pyramid_levels: must be in 0..8", "pyramid_levels");
  if (!positive(config.ransac_threshold_px)) return Error("FeatureTrackerConfig.ransac_threshold_px: must be positive", "ransac_threshold_px");
  if (!positive(config.stereo_epipolar_px)) return Error("FeatureTrackerConfig.stereo_epipolar_px: must be positive", "stereo_epipolar_px");
  if (!(config.detector_refill_share > 0.0 && config.detector_refill_share <= 1.0)) {
    return Error("FeatureTrackerConfig.detector_refill_share: must be in (0, 1]", "detector_refill_share");
  }
  return ok_status();
}

struct FeatureTracker::State {
  FeatureTrackerConfig config;
  cv::Size image_size;
  PinholeCamera left;
  std::optional<PinholeCamera> right;
  Eigen::Matrix3d essential = Eigen::Matrix3d::Zero();  // x_right^T E x_left = 0
  Eigen::Matrix3d R_right_left = Eigen::Matrix3d::Identity();
  // The previous left image's optical-flow pyramid (with its derivatives): each image's is built
  // once and serves the flow from the previous image, to the right image and to the next one.
  std::vector<cv::Mat> previous_pyramid;
  std::vector<cv::Point2f> points;
  std::vector<uint64_t> ids;
  std::map<uint64_t, cv::Point2f> right_points;  // last right-image position per id
  uint64_t next_id = 0;

  Result<TrackedFrame> track(const cv::Mat& left_image, const cv::Mat* right_image, const cv::Mat& static_mask);
  void track_over_time(const std::vector<cv::Mat>& pyramid, TrackedFrame& frame);
  // Ends the tracks on the mask's zeros.
  void drop_masked(const cv::Mat& static_mask, TrackedFrame& frame);
  void detect(const cv::Mat& grey, const cv::Mat& static_mask, TrackedFrame& frame);
  void match_right(const std::vector<cv::Mat>& pyramid, const std::vector<cv::Mat>& right_pyramid, TrackedFrame& frame);
  /// An image's pyramid as cv::calcOpticalFlowPyrLK builds it for this window and these levels
  /// (the same flow, built once).
  std::vector<cv::Mat> pyramid_of(const cv::Mat& grey) const {
    std::vector<cv::Mat> pyramid;
    cv::buildOpticalFlowPyramid(grey, pyramid, cv::Size(config.window_px, config.window_px), config.pyramid_levels, true);
    return pyramid;
  }
};

namespace {

Status check_camera(const PinholeCamera& camera, const char* which) {
  if (!positive(camera.fx) || !positive(camera.fy)) return Error(fmt::format("FeatureTracker: the {} camera's focal lengths must be positive", which), "camera");
  return ok_status();
}

}  // namespace

FeatureTracker::FeatureTracker(std::unique_ptr<State> state) : state_(std::move(state)) {}
FeatureTracker::~FeatureTracker() = default;

Result<std::unique_ptr<FeatureTracker>> FeatureTracker::create(const PinholeCamera& camera, cv::Size image_size, const FeatureTrackerConfig& config) {
  HANZO_RETURN_IF_ERROR(validate(config));
  HANZO_RETURN_IF_ERROR(check_camera(camera, "left"));
  if (image_size.width < 32 || image_size.height < 32)
    return Error(fmt::format("FeatureTracker: image size {}x{} is under 32x32", image_size.width, image_size.height), "image_size");
  auto state = std::make_unique<State>();
  state->config = config;
  state->image_size = image_size;
  state->left = camera;
  return std::unique_ptr<FeatureTracker>(new FeatureTracker(std::move(state)));
}

Result<std::unique_ptr<FeatureTracker>> FeatureTracker::create_stereo(const PinholeCamera& left, const PinholeCamera& right, const SE3& T_left_right,
                                                                     cv::Size image_size, const FeatureTrackerConfig& config) {
  std::unique_ptr<FeatureTracker> tracker;
  HANZO_ASSIGN_OR_RETURN(tracker, create(left, image_size, config));
  HANZO_RETURN_IF_ERROR(check_camera(right, "right"));
  if (!(T_left_right.translation().norm() >= 1e-3)) return Error("FeatureTracker: the stereo cameras are less than 1 mm apart", "T_left_right");
  const SE3 T_right_left = T_left_right.inverse();
  tracker->state_->right = right;
  tracker->state_->R_right_left = T_right_left.rotation().matrix();
  tracker->state_->essential = SO3::hat(T_right_left.translation()) * T_right_left.rotation().matrix();
  return tracker;
}

Result<TrackedFrame> FeatureTracker::track(const cv::Mat& image, const StaticMask& static_mask) { return state_->track(image, nullptr, static_mask.pixels); }

Result<TrackedFrame> FeatureTracker::track(const cv::Mat& left, const cv::Mat& right, const StaticMask& static_mask) {
  if (!state_->right) return Error("FeatureTracker: a stereo pair given to a monocular tracker", "image");
  return state_->track(left, &right, static_mask.pixels);
}

Result<TrackedFrame> FeatureTracker::State::track(const cv::Mat& left_image, const cv::Mat* right_image, const cv::Mat& static_mask) {
  if (!static_mask.empty() && (static_mask.type() != CV_8UC1 || static_mask.size() != image_size)) {
    return Error(fmt::format("static mask: {} x {} {}, expected 8-bit single channel of the image's {} x {}", static_mask.cols, static_mask.rows,
                             cv::typeToString(static_mask.type()), image_size.width, image_size.height), "static_mask");
  }
  cv::Mat grey;
  HANZO_ASSIGN_OR_RETURN(grey, to_grey(left_image, image_size, "left"));
  cv::Mat right_grey;
  if (right_image) {
    HANZO_ASSIGN_OR_RETURN(right_grey, to_grey(*right_image, image_size, "right"));
  }
  TrackedFrame frame;
  std::vector<cv::Mat> pyramid = pyramid_of(grey);
  track_over_time(pyramid, frame);
  if (!static_mask.empty()) drop_masked(static_mask, frame);
  detect(grey, static_mask, frame);

  // Features whose pixel does not undistort are dropped from the tracks too.
  std::vector<cv::Point2f> kept_points;
  std::vector<uint64_t> kept_ids;
  for (size_t i = 0; i < points.size(); ++i) {
    if (const std::optional<Eigen::Vector2d> coordinates = normalized(left, points[i])) {
      frame.observations.push_back({ids[i], 0, *coordinates});
      kept_points.push_back(points[i]);
      kept_ids.push_back(ids[i]);
    }
  }
  points = std::move(kept_points);
  ids = std::move(kept_ids);
  if (right_image) match_right(pyramid, pyramid_of(right_grey), frame);
  previous_pyramid = std::move(pyramid);
  return frame;
}

void FeatureTracker::State::track_over_time(const std::vector<cv::Mat>& pyramid, TrackedFrame& frame) {
  if (previous_pyramid.empty() || points.empty()) return;
  std::vector<cv::Point2f> moved;
  std::vector<unsigned char> status;
  std::vector<float> error;
  const cv::Size window(config.window_px, config.window_px);
  cv::calcOpticalFlowPyrLK(previous_pyramid, pyramid, points, moved, status, error, window, config.pyramid_levels);
  std::vector<cv::Point2f> before, after;
  std::vector<uint64_t> tracked_ids;
  std::vector<double> displacements;
  for (size_t i = 0; i < points.size(); ++i) {
    if (!status[i] || !inside(moved[i], image_size)) continue;
    before.push_back(points[i]);
    after.push_back(moved[i]);
    tracked_ids.push_back(ids[i]);
    displacements.push_back(std::hypot(moved[i].x - points[i].x, moved[i].y - points[i].y));
  }
  std::vector<unsigned char> inlier(after.size(), 1);
  if (after.size() >= 8) {
    std::nth_element(displacements.begin(), displacements.begin() + static_cast<long>(displacements.size() / 2), displacements.end());
    if (displacements[displacements.size() / 2] > 1.0) {
      // RANSAC on undistorted pixels (normalized coordinates scaled by the focal length).
      std::vector<cv::Point2f> undistorted_before, undistorted_after;
      std::vector<size_t> index;
      for (size_t i = 0; i < after.size(); ++i) {
        const std::optional<Eigen::Vector2d> a = normalized(left, before[i]), b = normalized(left, after[i]);
        if (!a || !b) continue;
        undistorted_before.emplace_back(static_cast<float>(left.fx * a->x()), static_cast<float>(left.fy * a->y()));
        undistorted_after.emplace_back(static_cast<float>(left.fx * b->x()), static_cast<float>(left.fy * b->y()));
        index.push_back(i);
      }
      if (index.size() >= 8) {
        std::vector<unsigned char> mask;
        const cv::Mat fundamental =
            cv::findFundamentalMat(undistorted_before, undistorted_after, cv::FM_RANSAC, config.ransac_threshold_px, 0.99, mask);
        if (!fundamental.empty() && mask.size() == index.size()) {
          for (size_t k = 0; k < index.size(); ++k) inlier[index[k]] = mask[k];
        }
      }
    }
  }
  points.clear();
  ids.clear();
  for (size_t i = 0; i < after.size(); ++i) {
    if (!inlier[i]) {
      ++frame.rejected_ransac;
      continue;
    }
    points.push_back(after[i]);
    ids.push_back(tracked_ids[i]);
  }
  frame.tracked = static_cast<int>(points.size());
}

namespace {

// Shi-Tomasi scores (cv::cornerMinEigenVal), their 3 x 3 local maxima over min_image_quality of the
// image's strongest where `free` is set, into the candidates of their cell.
void detect_corners(const cv::Mat& grey, const cv::Mat& free, double min_image_quality, const std::function<int(const cv::Point2f&)>& cell_of,
                    std::vector<std::vector<std::pair<float, cv::Point>>>& candidates) {
  cv::Mat score, dilated;
  cv::cornerMinEigenVal(grey, score, 3, 3);
  cv::dilate(score, dilated, cv::Mat());
  double image_best = 0.0;
  cv::minMaxLoc(score, nullptr, &image_best);
  const float floor = static_cast<float>(min_image_quality * image_best);
  for (int y = 1; y < grey.rows - 1; ++y) {
    const float* value = score.ptr<float>(y);
    const float* maximum = dilated.ptr<float>(y);
    const unsigned char* open = free.ptr<unsigned char>(y);
    for (int x = 1; x < grey.cols - 1; ++x) {
      if (value[x] > floor && value[x] == maximum[x] && open[x]) {
        candidates[static_cast<size_t>(cell_of(cv::Point2f(static_cast<float>(x), static_cast<float>(y))))].emplace_back(value[x], cv::Point(x, y));
      }
    }
  }
}

}  // namespace

void FeatureTracker::State::drop_masked(const cv::Mat& static_mask, TrackedFrame& frame) {
  std::size_t kept = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const cv::Point pixel(std::clamp(static_cast<int>(std::lround(points[i].x)), 0, image_size.width - 1),
                          std::clamp(static_cast<int>(std::lround(points[i].y)), 0, image_size.height - 1));
    if (static_mask.at<unsigned char>(pixel) == 0) {
      ++frame.masked;
      continue;
    }
    points[kept] = points[i];
    ids[kept++] = ids[i];
  }
  points.resize(kept);
  ids.resize(kept);
  frame.tracked = static_cast<int>(kept);
}

void FeatureTracker::State::detect(const cv::Mat& grey, const cv::Mat& static_mask, TrackedFrame& frame) {
  if (static_cast<int>(points.size()) >= config.max_features) return;
  if (config.detector && static_cast<double>(points.size()) >= config.detector_refill_share * config.max_features) return;
  const int columns = config.grid_columns, rows = config.grid_rows;
  const int per_cell = (config.max_features + columns * rows - 1) / (columns * rows);
  auto cell_of = [&](const cv::Point2f& point) {
    const int column = std::clamp(static_cast<int>(point.x * static_cast<float>(columns) / static_cast<float>(image_size.width)), 0, columns - 1);
    const int row = std::clamp(static_cast<int>(point.y * static_cast<float>(rows) / static_cast<float>(image_size.height)), 0, rows - 1);
    return row * columns + column;
  };
  std::vector<int> in_cell(static_cast<size_t>(columns * rows), 0);
  cv::Mat free = static_mask.empty() ? cv::Mat(image_size, CV_8UC1, cv::Scalar(255)) : static_mask.clone();
  const int radius = static_cast<int>(std::ceil(config.min_distance_px));
  for (const cv::Point2f& point : points) {
    ++in_cell[static_cast<size_t>(cell_of(point))];
    cv::circle(free, point, radius, cv::Scalar(0), cv::FILLED);
  }

  std::vector<std::vector<std::pair<float, cv::Point>>> candidates(static_cast<size_t>(columns * rows));
  if (config.detector) {
    // The detector's keypoints (its scores), grouped by cell, strongest first.
    Result<ImageFeatures> detected = config.detector->extract(grey);
    if (!detected) {
      logger()->warn("feature tracker: {} detection failed: {}", config.detector->name(), detected.error().message);
      return;
    }
    for (const cv::KeyPoint& keypoint : detected->keypoints) {
      const cv::Point pixel(static_cast<int>(std::lround(keypoint.pt.x)), static_cast<int>(std::lround(keypoint.pt.y)));
      if (pixel.x < 0 || pixel.y < 0 || pixel.x >= image_size.width || pixel.y >= image_size.height || !free.at<unsigned char>(pixel)) continue;
      candidates[static_cast<size_t>(cell_of(keypoint.pt))].emplace_back(keypoint.response, pixel);
    }
  } else {
    detect_corners(grey, free, config.min_image_quality, cell_of, candidates);
  }
  auto take = [&](const cv::Point& pixel) {
    if (!free.at<unsigned char>(pixel)) return false;
    points.emplace_back(static_cast<float>(pixel.x), static_cast<float>(pixel.y));
    ids.push_back(next_id++);
    ++frame.new_features;
    cv::circle(free, pixel, radius, cv::Scalar(0), cv::FILLED);
    return true;
  };
  // Each cell its share; what cells without texture leave goes to the strongest corners left.
  std::vector<std::pair<float, cv::Point>> left_over;
  for (size_t cell = 0; cell < candidates.size(); ++cell) {
    std::vector<std::pair<float, cv::Point>>& list = candidates[cell];
    if (list.empty()) continue;
    std::sort(list.begin(), list.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    const float cell_floor = static_cast<float>(config.quality_level) * list.front().first;
    for (const auto& candidate : list) {
      if (candidate.first < cell_floor) break;
      if (in_cell[cell] < per_cell && static_cast<int>(points.size()) < config.max_features) {
        if (take(candidate.second)) ++in_cell[cell];
      } else {
        left_over.push_back(candidate);
      }
    }
  }
  std::sort(left_over.begin(), left_over.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  for (const auto& candidate : left_over) {
    if (static_cast<int>(points.size()) >= config.max_features) break;
    take(candidate.second);
  }
}

void FeatureTracker::State::match_right(const std::vector<cv::Mat>& pyramid, const std::vector<cv::Mat>& right_pyramid, TrackedFrame& frame) {
  std::map<uint64_t, cv::Point2f> matched;
  if (!points.empty()) {
    std::vector<cv::Point2f> guess;
    for (size_t i = 0; i < points.size(); ++i) {
      // The last right position, else where the point would be at infinite depth.
      const auto last = right_points.find(ids[i]);
      std::optional<Eigen::Vector2d> at_infinity;
      if (last == right_points.end()) {
        if (const std::optional<Eigen::Vector2d> coordinates = normalized(left, points[i])) at_infinity = right->project(R_right_left * coordinates->homogeneous());
      }
      guess.push_back(last != right_points.end() ? last->second
                      : at_infinity            ? cv::Point2f(static_cast<float>(at_infinity->x()), static_cast<float>(at_infinity->y()))
                                               : points[i]);
    }
    std::vector<cv::Point2f> back = points;
    std::vector<unsigned char> status, back_status;
    std::vector<float> error;
    const cv::Size window(config.window_px, config.window_px);
    const cv::TermCriteria criteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01);
    cv::calcOpticalFlowPyrLK(pyramid, right_pyramid, points, guess, status, error, window, config.pyramid_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
    cv::calcOpticalFlowPyrLK(right_pyramid, pyramid, guess, back, back_status, error, window, config.pyramid_levels, criteria, cv::OPTFLOW_USE_INITIAL_FLOW);
    for (size_t i = 0; i < points.size(); ++i) {
      if (!status[i] || !back_status[i] || !inside(guess[i], image_size)) continue;
      if (std::hypot(back[i].x - points[i].x, back[i].y - points[i].y) > 1.0) continue;
      const std::optional<Eigen::Vector2d> left_coordinates = normalized(left, points[i]);
      const std::optional<Eigen::Vector2d> right_coordinates = normalized(*right, guess[i]);
      if (!left_coordinates || !right_coordinates) continue;
      const Eigen::Vector3d line = essential * left_coordinates->homogeneous();
      const double distance = std::abs(right_coordinates->homogeneous().dot(line)) / line.head<2>().norm() * right->fx;
      if (!(distance <= config.stereo_epipolar_px)) continue;
      frame.observations.push_back({ids[i], 1, *right_coordinates});
      matched[ids[i]] = guess[i];
    }
  }
  frame.stereo_matches = static_cast<int>(matched.size());
  right_points = std::move(matched);
}

}  // namespace hanzo::fusion::vision
