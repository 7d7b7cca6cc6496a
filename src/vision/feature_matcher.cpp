#include "hanzo/fusion/vision/feature_matcher.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/core.hpp>

namespace hanzo::fusion::vision {
namespace {

// Keeps one match per train keypoint: the one with the smallest distance.
std::vector<FeatureMatch> unique_by_train(std::vector<FeatureMatch> matches, std::size_t train_count) {
  std::vector<int> owner(train_count, -1);
  for (std::size_t i = 0; i < matches.size(); ++i) {
    int& current = owner[static_cast<std::size_t>(matches[i].train)];
    if (current < 0 || matches[i].distance < matches[static_cast<std::size_t>(current)].distance) current = static_cast<int>(i);
  }
  std::vector<FeatureMatch> kept;
  for (std::size_t i = 0; i < matches.size(); ++i) {
    if (owner[static_cast<std::size_t>(matches[i].train)] == static_cast<int>(i)) kept.push_back(matches[i]);
  }
  return kept;
}

// Every query-train distance of float descriptors (kFloatDistanceScale x Euclidean), from the
// dot products of one matrix product: |a - b|^2 = |a|^2 + |b|^2 - 2 a.b.
cv::Mat float_distances(const cv::Mat& query, const cv::Mat& train) {
  cv::Mat dot;
  cv::gemm(query, train, 1.0, cv::noArray(), 0.0, dot, cv::GEMM_2_T);
  cv::Mat query_norms, train_norms;
  cv::reduce(query.mul(query), query_norms, 1, cv::REDUCE_SUM);
  cv::reduce(train.mul(train), train_norms, 1, cv::REDUCE_SUM);
  cv::Mat distances(dot.size(), CV_32SC1);
  for (int q = 0; q < dot.rows; ++q) {
    const float* row = dot.ptr<float>(q);
    int* out = distances.ptr<int>(q);
    for (int t = 0; t < dot.cols; ++t) {
      const float squared = std::max(0.0F, query_norms.at<float>(q) + train_norms.at<float>(t) - 2.0F * row[t]);
      out[t] = static_cast<int>(std::lround(kFloatDistanceScale * std::sqrt(squared)));
    }
  }
  return distances;
}

int second_or_none(const NearestCandidates& candidates) {
  return candidates.second == std::numeric_limits<int>::max() ? -1 : candidates.second;
}

}  // namespace

int descriptor_distance(const cv::Mat& descriptors_a, int a, const cv::Mat& descriptors_b, int b) {
  if (descriptors_a.type() == CV_8UC1) return hamming_distance(descriptors_a.ptr<unsigned char>(a), descriptors_b.ptr<unsigned char>(b));
  const float* x = descriptors_a.ptr<float>(a);
  const float* y = descriptors_b.ptr<float>(b);
  double squared = 0.0;
  for (int i = 0; i < descriptors_a.cols; ++i) squared += (x[i] - y[i]) * (x[i] - y[i]);
  return static_cast<int>(std::lround(kFloatDistanceScale * std::sqrt(squared)));
}

int descriptor_distance_limit(const cv::Mat& descriptors, int max_hamming_bits, double max_euclidean) {
  return descriptors.type() == CV_8UC1 ? max_hamming_bits : static_cast<int>(std::lround(kFloatDistanceScale * max_euclidean));
}

std::vector<FeatureMatch> match_descriptors(const cv::Mat& query_descriptors, const cv::Mat& train_descriptors,
                                            const DescriptorMatcherConfig& config) {
  std::vector<FeatureMatch> matches;
  if (query_descriptors.empty() || train_descriptors.empty()) return matches;
  const int queries = query_descriptors.rows, trains = train_descriptors.rows;
  std::vector<NearestCandidates> nearest_query(static_cast<std::size_t>(queries));
  std::vector<NearestCandidates> nearest_train(static_cast<std::size_t>(trains));  // for the mutual check
  const bool binary = query_descriptors.type() == CV_8UC1;
  const cv::Mat distances = binary ? cv::Mat() : float_distances(query_descriptors, train_descriptors);
  for (int q = 0; q < queries; ++q) {
    const unsigned char* query = query_descriptors.ptr<unsigned char>(q);
    const int* float_row = binary ? nullptr : distances.ptr<int>(q);
    NearestCandidates& best_for_query = nearest_query[static_cast<std::size_t>(q)];
    for (int t = 0; t < trains; ++t) {
      const int distance = binary ? hamming_distance(query, train_descriptors.ptr<unsigned char>(t)) : float_row[t];
      best_for_query.offer(t, distance);
      NearestCandidates& best_for_train = nearest_train[static_cast<std::size_t>(t)];
      if (distance < best_for_train.best) {
        best_for_train.best = distance;
        best_for_train.index = q;
      }
    }
  }
  for (int q = 0; q < queries; ++q) {
    const NearestCandidates& best = nearest_query[static_cast<std::size_t>(q)];
    const bool passes = binary ? best.passes(config.ratio, config.max_distance)
                               : best.passes(config.float_ratio, descriptor_distance_limit(query_descriptors, config.max_distance, config.max_float_distance));
    if (!passes) continue;
    if (config.mutual && nearest_train[static_cast<std::size_t>(best.index)].index != q) continue;
    matches.push_back({q, best.index, best.best, second_or_none(best)});
  }
  return matches;
}

std::vector<FeatureMatch> match_guided(const ImageFeatures& query, const ImageFeatures& train, GeometryModel model,
                                       const cv::Matx33d& geometry, const GuidedMatcherConfig& config) {
  std::vector<FeatureMatch> matches;
  if (query.keypoints.empty() || train.keypoints.empty()) return matches;
  // Train keypoints in a grid of radius-sized cells, for the homography's neighbourhood search.
  const double cell = std::max(config.radius_px, 1.0);
  const int columns = static_cast<int>(std::ceil(train.image_size.width / cell)) + 1;
  const int rows = static_cast<int>(std::ceil(train.image_size.height / cell)) + 1;
  std::vector<std::vector<int>> grid(static_cast<std::size_t>(columns * rows));
  for (std::size_t t = 0; t < train.keypoints.size(); ++t) {
    const int column = std::clamp(static_cast<int>(train.keypoints[t].pt.x / cell), 0, columns - 1);
    const int row = std::clamp(static_cast<int>(train.keypoints[t].pt.y / cell), 0, rows - 1);
    grid[static_cast<std::size_t>(row * columns + column)].push_back(static_cast<int>(t));
  }
  const double radius_squared = config.radius_px * config.radius_px;
  auto compatible_octave = [&](const cv::KeyPoint& a, const cv::KeyPoint& b) {
    return config.max_octave_difference < 0 || std::abs(a.octave - b.octave) <= config.max_octave_difference;
  };
  for (std::size_t q = 0; q < query.keypoints.size(); ++q) {
    const cv::KeyPoint& keypoint = query.keypoints[q];
    const cv::Vec3d x(keypoint.pt.x, keypoint.pt.y, 1.0);
    const cv::Vec3d mapped = geometry * x;
    NearestCandidates nearest;
    auto consider = [&](int t) {
      const cv::KeyPoint& candidate = train.keypoints[static_cast<std::size_t>(t)];
      if (!compatible_octave(keypoint, candidate)) return;
      nearest.offer(t, descriptor_distance(query.descriptors, static_cast<int>(q), train.descriptors, t));
    };
    if (model == GeometryModel::kHomography) {
      if (std::abs(mapped[2]) < 1e-12) continue;
      const double u = mapped[0] / mapped[2], v = mapped[1] / mapped[2];
      const int column = static_cast<int>(std::floor(u / cell)), row = static_cast<int>(std::floor(v / cell));
      for (int r = row - 1; r <= row + 1; ++r) {
        for (int c = column - 1; c <= column + 1; ++c) {
          if (r < 0 || c < 0 || r >= rows || c >= columns) continue;
          for (int t : grid[static_cast<std::size_t>(r * columns + c)]) {
            const double du = train.keypoints[static_cast<std::size_t>(t)].pt.x - u;
            const double dv = train.keypoints[static_cast<std::size_t>(t)].pt.y - v;
            if (du * du + dv * dv <= radius_squared) consider(t);
          }
        }
      }
    } else {
      // Epipolar line l = F x in the train image: a u + b v + c = 0.
      const double norm = std::hypot(mapped[0], mapped[1]);
      if (norm < 1e-12) continue;
      for (std::size_t t = 0; t < train.keypoints.size(); ++t) {
        const cv::Point2f& p = train.keypoints[t].pt;
        if (std::abs(mapped[0] * p.x + mapped[1] * p.y + mapped[2]) <= config.radius_px * norm) consider(static_cast<int>(t));
      }
    }
    const int max_distance = descriptor_distance_limit(query.descriptors, config.max_distance, config.max_float_distance);
    if (nearest.passes(config.ratio, max_distance)) matches.push_back({static_cast<int>(q), nearest.index, nearest.best, second_or_none(nearest)});
  }
  return unique_by_train(std::move(matches), train.keypoints.size());
}

}  // namespace hanzo::fusion::vision
