// Differentiable keypoint detection (DKD, ALIKE sec. III-B) at inference, on the score map as an
// OpenCV image: the upstream soft_detect's simple_nms (max pooling = dilation with -inf
// outside), border removal, threshold / top-k selection and soft-argmax, value for value.
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include <opencv2/imgproc.hpp>

#include "learned_network.hpp"

namespace hanzo::fusion::ai {
namespace {

// (2 radius + 1)^2 max pooling with stride 1, -inf outside (torch's max_pool2d with padding).
cv::Mat max_pool(const cv::Mat& map, int radius) {
  cv::Mat pooled;
  cv::dilate(map, pooled, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * radius + 1, 2 * radius + 1)), cv::Point(-1, -1), 1,
             cv::BORDER_CONSTANT, cv::Scalar::all(-std::numeric_limits<double>::infinity()));
  return pooled;
}

// Non-maximum suppression with two rounds that revive maxima suppressed only by suppressed
// neighbours (SuperPoint's simple_nms): the scores where a maximum is kept, 0 elsewhere.
cv::Mat simple_nms(const cv::Mat& scores, int radius) {
  cv::Mat max_mask = scores == max_pool(scores, radius);  // CV_8U 255 / 0
  for (int round = 0; round < 2; ++round) {
    cv::Mat suppressed = max_pool(max_mask, radius) > 0;
    cv::Mat kept_scores = scores.clone();
    kept_scores.setTo(0.0F, suppressed);
    cv::Mat new_max = (kept_scores == max_pool(kept_scores, radius)) & ~suppressed;
    max_mask |= new_max;
  }
  cv::Mat kept = cv::Mat::zeros(scores.size(), CV_32FC1);
  scores.copyTo(kept, max_mask);
  return kept;
}

// Bilinear value of `map` at (x, y) pixels, zeros outside (grid_sample, align_corners).
float bilinear(const cv::Mat& map, float x, float y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const float fx = x - static_cast<float>(x0), fy = y - static_cast<float>(y0);
  auto at = [&](int u, int v) { return u < 0 || v < 0 || u >= map.cols || v >= map.rows ? 0.0F : map.at<float>(v, u); };
  return at(x0, y0) * (1 - fx) * (1 - fy) + at(x0 + 1, y0) * fx * (1 - fy) + at(x0, y0 + 1) * (1 - fx) * fy + at(x0 + 1, y0 + 1) * fx * fy;
}

}  // namespace

std::pair<at::Tensor, at::Tensor> detect_keypoints(const at::Tensor& score_map, const LearnedFeatureConfig& config) {
  const int radius = config.nms_radius;
  const at::Tensor contiguous = score_map.contiguous();
  const cv::Mat scores(static_cast<int>(score_map.size(2)), static_cast<int>(score_map.size(3)), CV_32FC1, contiguous.data_ptr<float>());
  const int height = scores.rows, width = scores.cols;
  cv::Mat nms = simple_nms(scores, radius);
  nms.rowRange(0, radius + 1).setTo(0.0F);
  nms.colRange(0, radius + 1).setTo(0.0F);
  nms.rowRange(height - radius, height).setTo(0.0F);
  nms.colRange(width - radius, width).setTo(0.0F);

  std::vector<int> indices;  // raster order, as nonzero() gives them
  auto select_above = [&](float threshold) {
    indices.clear();
    for (int v = 0; v < height; ++v) {
      const float* row = nms.ptr<float>(v);
      for (int u = 0; u < width; ++u) {
        if (row[u] > threshold) indices.push_back(v * width + u);
      }
    }
  };
  const auto by_score = [&](int a, int b) { return scores.ptr<float>()[a] > scores.ptr<float>()[b]; };
  if (config.score_threshold > 0.0F) {
    select_above(config.score_threshold);
    if (indices.empty()) select_above(static_cast<float>(cv::mean(scores)[0]));
    if (static_cast<int>(indices.size()) > config.max_keypoints) {
      std::stable_sort(indices.begin(), indices.end(), by_score);
      indices.resize(static_cast<std::size_t>(config.max_keypoints));
    }
  } else {
    indices.resize(static_cast<std::size_t>(width * height));
    std::iota(indices.begin(), indices.end(), 0);
    const auto by_nms = [&](int a, int b) { return nms.ptr<float>()[a] > nms.ptr<float>()[b]; };
    const std::size_t keep = std::min<std::size_t>(indices.size(), static_cast<std::size_t>(config.max_keypoints));
    std::partial_sort(indices.begin(), indices.begin() + static_cast<std::ptrdiff_t>(keep), indices.end(), by_nms);
    indices.resize(keep);
  }

  const int count = static_cast<int>(indices.size());
  at::Tensor keypoints = at::empty({count, 2}, at::kFloat), values = at::empty({count}, at::kFloat);
  auto points = keypoints.accessor<float, 2>();
  auto point_scores = values.accessor<float, 1>();
  const int kernel = 2 * radius + 1;
  std::vector<float> window(static_cast<std::size_t>(kernel * kernel));
  for (int i = 0; i < count; ++i) {
    const int u = indices[static_cast<std::size_t>(i)] % width, v = indices[static_cast<std::size_t>(i)] / width;
    float x = static_cast<float>(u), y = static_cast<float>(v);
    if (config.subpixel) {
      // Soft-argmax over the window (zeros outside the map), temperature 0.1.
      float largest = -std::numeric_limits<float>::infinity();
      for (int dy = -radius, k = 0; dy <= radius; ++dy) {
        for (int dx = -radius; dx <= radius; ++dx, ++k) {
          const int uu = u + dx, vv = v + dy;
          window[static_cast<std::size_t>(k)] = uu < 0 || vv < 0 || uu >= width || vv >= height ? 0.0F : scores.at<float>(vv, uu);
          largest = std::max(largest, window[static_cast<std::size_t>(k)]);
        }
      }
      float sum = 0.0F, sum_x = 0.0F, sum_y = 0.0F;
      for (int dy = -radius, k = 0; dy <= radius; ++dy) {
        for (int dx = -radius; dx <= radius; ++dx, ++k) {
          const float weight = std::exp((window[static_cast<std::size_t>(k)] - largest) / 0.1F);
          sum += weight;
          sum_x += weight * static_cast<float>(dx);
          sum_y += weight * static_cast<float>(dy);
        }
      }
      x += sum_x / sum;
      y += sum_y / sum;
    }
    points[i][0] = x / static_cast<float>(width - 1) * 2.0F - 1.0F;
    points[i][1] = y / static_cast<float>(height - 1) * 2.0F - 1.0F;
    // The score where the keypoint is, through the normalized position as grid_sample reads it.
    const float read_x = (points[i][0] + 1.0F) / 2.0F * static_cast<float>(width - 1);
    const float read_y = (points[i][1] + 1.0F) / 2.0F * static_cast<float>(height - 1);
    point_scores[i] = bilinear(scores, read_x, read_y);
  }
  return {keypoints, values};
}

}  // namespace hanzo::fusion::ai
