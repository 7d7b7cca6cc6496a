#include "hanzo/fusion/vision/orb_extractor.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::vision {
namespace {

constexpr int kPatchSize = 31;
constexpr int kHalfPatch = kPatchSize / 2;
// Corners closer than this to a level's border are not kept: the orientation disc (radius 15)
// and the rotated BRIEF pattern (OpenCV pads each level by the same margin) must fit.
constexpr int kLevelBorder = 19;

// Half-widths of the orientation disc per row: u_max[v] = max |u| with u^2 + v^2 <= 15^2,
// symmetric in u and v (the construction of the ORB paper's reference code).
std::vector<int> disc_half_widths() {
  std::vector<int> u_max(kHalfPatch + 1);
  const int v_split = static_cast<int>(std::floor(kHalfPatch * std::sqrt(2.0) / 2 + 1));
  const double radius_squared = static_cast<double>(kHalfPatch) * kHalfPatch;
  for (int v = 0; v <= v_split; ++v) u_max[v] = static_cast<int>(std::lround(std::sqrt(radius_squared - v * v)));
  // The rest by symmetry, so the disc is the same seen along rows and columns.
  for (int v = kHalfPatch, v0 = 0; v >= v_split; --v) {
    while (u_max[v0] == u_max[v0 + 1]) ++v0;
    u_max[v] = v0;
    ++v0;
  }
  return u_max;
}

// Orientation (degrees, [0, 360)) of the intensity centroid m10, m01 of the disc around a pixel
// (ORB eq. 2-3: theta = atan2(m01, m10)); the pixel is at least kHalfPatch from the border.
float intensity_centroid_angle(const cv::Mat& image, int column, int row, const std::vector<int>& u_max) {
  const auto step = static_cast<int>(image.step1());
  const unsigned char* centre = image.ptr<unsigned char>(row) + column;
  int m10 = 0, m01 = 0;
  for (int u = -kHalfPatch; u <= kHalfPatch; ++u) m10 += u * centre[u];
  for (int v = 1; v <= kHalfPatch; ++v) {
    int row_sum_difference = 0;
    for (int u = -u_max[v]; u <= u_max[v]; ++u) {
      const int below = centre[u + v * step], above = centre[u - v * step];
      row_sum_difference += below - above;
      m10 += u * (below + above);
    }
    m01 += v * row_sum_difference;
  }
  float angle = cv::fastAtan2(static_cast<float>(m01), static_cast<float>(m10));
  return angle >= 360.0f ? angle - 360.0f : angle;
}

// Harris corner measure det(M) - 0.04 trace(M)^2 of the 7 x 7 structure tensor M of Sobel
// gradients around a pixel at least 4 pixels inside the image (the ranking OpenCV's ORB uses:
// more repeatable under viewpoint change than FAST's contrast).
float harris_response(const cv::Mat& image, int column, int row) {
  constexpr int kHalfBlock = 3;
  const auto step = static_cast<int>(image.step1());
  long long xx = 0, yy = 0, xy = 0;
  for (int v = -kHalfBlock; v <= kHalfBlock; ++v) {
    const unsigned char* p = image.ptr<unsigned char>(row + v) + column;
    for (int u = -kHalfBlock; u <= kHalfBlock; ++u) {
      const unsigned char* q = p + u;
      const int dx = (q[1 - step] + 2 * q[1] + q[1 + step]) - (q[-1 - step] + 2 * q[-1] + q[-1 + step]);
      const int dy = (q[step - 1] + 2 * q[step] + q[step + 1]) - (q[-step - 1] + 2 * q[-step] + q[-step + 1]);
      xx += dx * dx;
      yy += dy * dy;
      xy += dx * dy;
    }
  }
  const double a = static_cast<double>(xx), b = static_cast<double>(yy), c = static_cast<double>(xy);
  return static_cast<float>(a * b - c * c - 0.04 * (a + b) * (a + b));
}

// Keypoints of one level in that level's pixels: FAST, per-cell adaptive threshold, Harris
// ranking within a cell, round-robin over cells until `budget` are taken.
std::vector<cv::KeyPoint> bucketed_corners(const cv::Mat& level_image, const cv::Mat& level_mask, int budget,
                                           const OrbExtractorConfig& config) {
  std::vector<cv::KeyPoint> corners;
  cv::FAST(level_image, corners, config.min_fast_threshold, true, cv::FastFeatureDetector::TYPE_9_16);
  const int columns = (level_image.cols + config.cell_size - 1) / config.cell_size;
  const int rows = (level_image.rows + config.cell_size - 1) / config.cell_size;
  std::vector<std::vector<cv::KeyPoint>> cells(static_cast<std::size_t>(columns * rows));
  for (const cv::KeyPoint& corner : corners) {
    const int u = cvRound(corner.pt.x), v = cvRound(corner.pt.y);
    if (u < kLevelBorder || v < kLevelBorder || u >= level_image.cols - kLevelBorder || v >= level_image.rows - kLevelBorder) continue;
    if (!level_mask.empty() && level_mask.at<unsigned char>(v, u) == 0) continue;
    cells[static_cast<std::size_t>((v / config.cell_size) * columns + u / config.cell_size)].push_back(corner);
  }
  const auto occupied = static_cast<std::size_t>(std::count_if(cells.begin(), cells.end(), [](const auto& cell) { return !cell.empty(); }));
  if (occupied == 0) return {};
  // Harris is measured on a cell's strongest FAST corners only: twice its fair share (and at
  // least 8), which bounds the cost on busy textures.
  const std::size_t measured = std::max<std::size_t>(8, 2 * (static_cast<std::size_t>(budget) / occupied + 1));
  // FAST's response is the corner's contrast threshold: the largest t at which it is a corner.
  const auto strong = static_cast<float>(config.initial_fast_threshold);
  auto by_response = [](const cv::KeyPoint& a, const cv::KeyPoint& b) { return a.response > b.response; };
  std::size_t deepest = 0;
  for (std::vector<cv::KeyPoint>& cell : cells) {
    std::sort(cell.begin(), cell.end(), by_response);
    if (!cell.empty() && cell.front().response >= strong) {
      cell.erase(std::find_if(cell.begin(), cell.end(), [&](const cv::KeyPoint& k) { return k.response < strong; }), cell.end());
    }
    if (cell.size() > measured) cell.resize(measured);
    for (cv::KeyPoint& corner : cell) corner.response = harris_response(level_image, cvRound(corner.pt.x), cvRound(corner.pt.y));
    std::sort(cell.begin(), cell.end(), by_response);
    deepest = std::max(deepest, cell.size());
  }
  std::vector<cv::KeyPoint> kept;
  std::vector<cv::KeyPoint> rank_round;
  for (std::size_t rank = 0; rank < deepest && static_cast<int>(kept.size()) < budget; ++rank) {
    rank_round.clear();
    for (const std::vector<cv::KeyPoint>& cell : cells) {
      if (rank < cell.size()) rank_round.push_back(cell[rank]);
    }
    // The last round may not fit: its strongest corners first.
    std::sort(rank_round.begin(), rank_round.end(), by_response);
    const std::size_t take = std::min(rank_round.size(), static_cast<std::size_t>(budget) - kept.size());
    kept.insert(kept.end(), rank_round.begin(), rank_round.begin() + static_cast<std::ptrdiff_t>(take));
  }
  return kept;
}

}  // namespace

Status validate(const OrbExtractorConfig& config) {
  if (config.max_features < 1 || config.max_features > 100000) {
    return Error(fmt::format("OrbExtractorConfig.max_features: {} is outside 1..100000", config.max_features), "max_features");
  }
  if (!(config.scale_factor > 1.0 && config.scale_factor <= 4.0)) {
    return Error(fmt::format("OrbExtractorConfig.scale_factor: {} is outside (1, 4]", config.scale_factor), "scale_factor");
  }
  if (config.pyramid_levels < 1 || config.pyramid_levels > 16) {
    return Error(fmt::format("OrbExtractorConfig.pyramid_levels: {} is outside 1..16", config.pyramid_levels), "pyramid_levels");
  }
  if (config.cell_size < 8 || config.cell_size > 256) {
    return Error(fmt::format("OrbExtractorConfig.cell_size: {} is outside 8..256", config.cell_size), "cell_size");
  }
  if (config.min_fast_threshold < 1 || config.initial_fast_threshold > 255 || config.min_fast_threshold > config.initial_fast_threshold) {
    return Error(fmt::format("OrbExtractorConfig: FAST thresholds must satisfy 1 <= min_fast_threshold ({}) <= "
                             "initial_fast_threshold ({}) <= 255",
                             config.min_fast_threshold, config.initial_fast_threshold),
                 "min_fast_threshold");
  }
  return ok_status();
}

OrbExtractor::OrbExtractor(OrbExtractorConfig config) : config_(config) {}

Result<ImageFeatures> OrbExtractor::extract(const cv::Mat& image, const cv::Mat& mask) const {
  if (Status valid = validate(config_); !valid) return valid.error();
  if (image.empty()) return Error("image: empty");
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3 && image.channels() != 4)) {
    return Error(fmt::format("image: type {} is not 8-bit grey, BGR or BGRA", cv::typeToString(image.type())));
  }
  if (image.cols < 2 * kPatchSize || image.rows < 2 * kPatchSize) {
    return Error(fmt::format("image: {} x {} pixels is smaller than {} x {}", image.cols, image.rows, 2 * kPatchSize, 2 * kPatchSize));
  }
  if (!mask.empty() && (mask.type() != CV_8UC1 || mask.size() != image.size())) {
    return Error(fmt::format("mask: {} {} x {} does not match the image ({} x {}, CV_8UC1 expected)", cv::typeToString(mask.type()),
                             mask.cols, mask.rows, image.cols, image.rows));
  }
  cv::Mat grey;
  if (image.channels() == 1) {
    grey = image;
  } else {
    cv::cvtColor(image, grey, image.channels() == 3 ? cv::COLOR_BGR2GRAY : cv::COLOR_BGRA2GRAY);
  }

  // Budget per level: a geometric series with ratio 1 / scale_factor summing to max_features.
  const double ratio = 1.0 / config_.scale_factor;
  std::vector<int> budgets(static_cast<std::size_t>(config_.pyramid_levels));
  double first = config_.max_features * (1.0 - ratio) / (1.0 - std::pow(ratio, config_.pyramid_levels));
  int assigned = 0;
  for (int level = 0; level < config_.pyramid_levels - 1; ++level) {
    budgets[static_cast<std::size_t>(level)] = static_cast<int>(std::lround(first * std::pow(ratio, level)));
    assigned += budgets[static_cast<std::size_t>(level)];
  }
  budgets.back() = std::max(0, config_.max_features - assigned);

  static const std::vector<int> u_max = disc_half_widths();
  ImageFeatures features;
  features.image_size = image.size();
  cv::Mat level_image = grey, level_mask = mask;
  int levels_used = 0;
  for (int level = 0; level < config_.pyramid_levels; ++level) {
    const double scale = std::pow(config_.scale_factor, level);
    if (level > 0) {
      const cv::Size size(static_cast<int>(std::lround(grey.cols / scale)), static_cast<int>(std::lround(grey.rows / scale)));
      if (size.width <= 2 * kLevelBorder + 1 || size.height <= 2 * kLevelBorder + 1) break;
      // Each level from the one before (a factor of scale_factor): resizing level 0 straight to
      // 1/3.6 with bilinear weights aliases, and the corners of aliased levels do not repeat.
      cv::resize(cv::Mat(level_image), level_image, size, 0, 0, cv::INTER_LINEAR);
      if (!mask.empty()) cv::resize(cv::Mat(level_mask), level_mask, size, 0, 0, cv::INTER_NEAREST);
    }
    levels_used = level + 1;
    std::vector<cv::KeyPoint> corners = bucketed_corners(level_image, level_mask, budgets[static_cast<std::size_t>(level)], config_);
    if (config_.subpixel && !corners.empty()) {
      std::vector<cv::Point2f> positions;
      for (const cv::KeyPoint& corner : corners) positions.push_back(corner.pt);
      cv::cornerSubPix(level_image, positions, cv::Size(2, 2), cv::Size(-1, -1), cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 5, 0.05));
      for (std::size_t i = 0; i < corners.size(); ++i) {
        // A refinement that wanders off (an edge, not a corner) keeps the FAST position.
        if (cv::norm(positions[i] - corners[i].pt) < 1.0) corners[i].pt = positions[i];
      }
    }
    for (cv::KeyPoint corner : corners) {
      corner.angle = intensity_centroid_angle(level_image, cvRound(corner.pt.x), cvRound(corner.pt.y), u_max);
      corner.octave = level;
      corner.size = static_cast<float>(kPatchSize * scale);
      // Pixel centres: resizing maps a level pixel u to (u + 0.5) k - 0.5 of level 0, k the
      // size ratio (a plain u k would shift a level-7 keypoint by 1.3 pixels towards the
      // origin: a bias geometry cannot tell from a wrong principal point).
      const float ratio_x = static_cast<float>(grey.cols) / static_cast<float>(level_image.cols);
      const float ratio_y = static_cast<float>(grey.rows) / static_cast<float>(level_image.rows);
      corner.pt = cv::Point2f((corner.pt.x + 0.5f) * ratio_x - 0.5f, (corner.pt.y + 0.5f) * ratio_y - 0.5f);
      // The level's mask is a resampled copy: the level-0 mask decides at the level-0 pixel.
      if (!mask.empty() && mask.at<unsigned char>(std::min(cvRound(corner.pt.y), mask.rows - 1), std::min(cvRound(corner.pt.x), mask.cols - 1)) == 0) {
        continue;
      }
      features.keypoints.push_back(corner);
    }
  }
  if (features.keypoints.empty()) {
    features.descriptors = cv::Mat(0, 32, CV_8UC1);
    return features;
  }
  // OpenCV's rotated BRIEF for the given keypoints (it keeps angle and octave; it may reorder).
  cv::Ptr<cv::ORB> brief = cv::ORB::create(config_.max_features, static_cast<float>(config_.scale_factor), levels_used, kLevelBorder, 0, 2,
                                           cv::ORB::HARRIS_SCORE, kPatchSize, config_.initial_fast_threshold);
  brief->compute(grey, features.keypoints, features.descriptors);
  if (features.descriptors.empty()) features.descriptors = cv::Mat(0, 32, CV_8UC1);
  return features;
}

}  // namespace hanzo::fusion::vision
