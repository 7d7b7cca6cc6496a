#include "hanzo/fusion/vision/landmark_map_alignment.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <fmt/format.h>

#include "hanzo/fusion/vision/feature_matcher.hpp"

namespace hanzo::fusion::vision {

namespace {

struct Similarity {
  double scale = 1.0;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Vector3d apply(const Eigen::Vector3d& x) const { return scale * (rotation * x) + translation; }
};

/// Umeyama's least-squares similarity taking points_b onto points_a (3 x N each).
std::optional<Similarity> fit(const Eigen::Matrix3Xd& points_a, const Eigen::Matrix3Xd& points_b, bool with_scale) {
  const Eigen::Matrix4d T = Eigen::umeyama(points_b, points_a, with_scale);
  if (!T.allFinite()) return std::nullopt;
  Similarity similarity;
  similarity.scale = with_scale ? T.block<3, 1>(0, 0).norm() : 1.0;
  if (!(similarity.scale > 0.0)) return std::nullopt;
  similarity.rotation = T.block<3, 3>(0, 0) / similarity.scale;
  similarity.translation = T.block<3, 1>(0, 3);
  return similarity;
}

/// The landmarks keyframe k of `map` sees whose uncertainty is within max_relative_std of their
/// distance to it.
std::vector<uint32_t> certain_landmarks(const msgs::VisualLandmarkLayer& map, std::size_t k, double max_relative_std) {
  const Eigen::Vector3f centre = map.keyframes[k].T_world_camera.position.cast<float>();
  std::vector<uint32_t> kept;
  for (uint32_t landmark : map.keyframes[k].landmarks) {
    const double depth = (map.positions[landmark] - centre).norm();
    if (map.position_std.empty() || map.position_std[landmark] <= max_relative_std * depth) kept.push_back(landmark);
  }
  return kept;
}

}  // namespace

Status LandmarkMapAlignmentConfig::validate() const {
  if (candidates < 1 || neighbour_keyframes < 0 || ransac_iterations < 1 || min_inliers < 3) {
    return Error("LandmarkMapAlignmentConfig: candidates >= 1, neighbour_keyframes >= 0, ransac_iterations >= 1 and min_inliers >= 3 are required");
  }
  if (!(descriptor_ratio > 0.0 && descriptor_ratio <= 1.0) || !(max_relative_std > 0.0) || !(inlier_ratio > 0.0) || !(min_inlier_distance >= 0.0) ||
      !(min_inlier_fraction >= 0.0 && min_inlier_fraction <= 1.0) || !(max_scale_change >= 1.0)) {
    return Error("LandmarkMapAlignmentConfig: descriptor_ratio in (0, 1], max_relative_std > 0, inlier_ratio > 0, min_inlier_distance >= 0, "
                 "min_inlier_fraction in [0, 1] and max_scale_change >= 1 are required");
  }
  return ok_status();
}

Result<LandmarkMapAligner> LandmarkMapAligner::create(const msgs::VisualLandmarkLayer& map_a, const LandmarkMapAlignmentConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  if (map_a.keyframes.empty()) return Error(fmt::format("visual landmark map of {}: no keyframes", map_a.camera));
  Result<LandmarkPlaceIndex> places = LandmarkPlaceIndex::create(map_a, config.places);
  if (!places) return places.error();
  return LandmarkMapAligner(map_a, std::move(*places), config);
}

Result<LandmarkMapLoop> LandmarkMapAligner::align(const msgs::VisualLandmarkLayer& map_b, const cv::Mat& descriptors_b, std::size_t keyframe_b) const {
  const msgs::VisualLandmarkLayer& map_a = *map_a_;
  if (map_b.descriptor_type != map_a.descriptor_type) {
    return Error(fmt::format("landmark maps: {} descriptors against {} (maps of one feature type are aligned)", map_b.descriptor_type, map_a.descriptor_type));
  }
  if (keyframe_b >= map_b.keyframes.size() || descriptors_b.rows != static_cast<int>(map_b.positions.size())) {
    return Error(fmt::format("landmark maps: keyframe {} of {}, {} descriptors for {} landmarks", keyframe_b, map_b.keyframes.size(), descriptors_b.rows,
                             map_b.positions.size()));
  }
  const std::vector<uint32_t> query = certain_landmarks(map_b, keyframe_b, config_.max_relative_std);
  if (static_cast<int>(query.size()) < config_.min_inliers) return Error(fmt::format("query keyframe: {} certain landmarks (< {})", query.size(), config_.min_inliers));
  cv::Mat query_descriptors;
  for (uint32_t landmark : query) query_descriptors.push_back(descriptors_b.row(static_cast<int>(landmark)));
  const bool with_scale = map_a.scale_free || map_b.scale_free;

  std::optional<LandmarkMapLoop> best;
  int most_pairs = 0, most_inliers = 0;
  for (const PlaceCandidate& candidate : places_.rank(query_descriptors, config_.candidates)) {
    const auto k = static_cast<std::size_t>(candidate.keyframe);
    std::vector<uint32_t> landmarks;
    const std::size_t first = k >= static_cast<std::size_t>(config_.neighbour_keyframes) ? k - static_cast<std::size_t>(config_.neighbour_keyframes) : 0;
    const std::size_t last = std::min(map_a.keyframes.size() - 1, k + static_cast<std::size_t>(config_.neighbour_keyframes));
    for (std::size_t j = first; j <= last; ++j) {
      const std::vector<uint32_t> seen = certain_landmarks(map_a, j, config_.max_relative_std);
      landmarks.insert(landmarks.end(), seen.begin(), seen.end());
    }
    std::sort(landmarks.begin(), landmarks.end());
    landmarks.erase(std::unique(landmarks.begin(), landmarks.end()), landmarks.end());
    cv::Mat candidate_descriptors;
    for (uint32_t landmark : landmarks) candidate_descriptors.push_back(places_.descriptors().row(static_cast<int>(landmark)));
    DescriptorMatcherConfig matcher;
    matcher.ratio = config_.descriptor_ratio;
    matcher.float_ratio = config_.descriptor_ratio;
    const std::vector<FeatureMatch> matches = candidate_descriptors.empty() ? std::vector<FeatureMatch>{} : match_descriptors(query_descriptors, candidate_descriptors, matcher);
    const auto pairs = static_cast<int>(matches.size());
    most_pairs = std::max(most_pairs, pairs);
    if (pairs < config_.min_inliers) continue;
    Eigen::Matrix3Xd points_a(3, pairs), points_b(3, pairs);
    Eigen::VectorXd tolerance(pairs);
    const Eigen::Vector3d centre_a = map_a.keyframes[k].T_world_camera.position;
    for (int i = 0; i < pairs; ++i) {
      points_b.col(i) = map_b.positions[query[static_cast<std::size_t>(matches[static_cast<std::size_t>(i)].query)]].cast<double>();
      points_a.col(i) = map_a.positions[landmarks[static_cast<std::size_t>(matches[static_cast<std::size_t>(i)].train)]].cast<double>();
      tolerance(i) = std::max(config_.min_inlier_distance, config_.inlier_ratio * (points_a.col(i) - centre_a).norm());
    }
    const auto inliers_of = [&](const Similarity& similarity) {
      std::vector<int> inliers;
      for (int i = 0; i < pairs; ++i) {
        if ((similarity.apply(points_b.col(i)) - points_a.col(i)).norm() <= tolerance(i)) inliers.push_back(i);
      }
      return inliers;
    };
    const auto plausible = [&](const Similarity& similarity) {
      return similarity.scale >= 1.0 / config_.max_scale_change && similarity.scale <= config_.max_scale_change;
    };
    std::mt19937 random(static_cast<uint32_t>(1000003 * keyframe_b + k));
    std::uniform_int_distribution<int> pick(0, pairs - 1);
    std::vector<int> best_inliers;
    Similarity best_similarity;
    for (int iteration = 0; iteration < config_.ransac_iterations; ++iteration) {
      std::array<int, 3> sample{pick(random), pick(random), pick(random)};
      if (sample[0] == sample[1] || sample[1] == sample[2] || sample[0] == sample[2]) continue;
      Eigen::Matrix3d sample_a, sample_b;
      for (int j = 0; j < 3; ++j) {
        sample_a.col(j) = points_a.col(sample[static_cast<std::size_t>(j)]);
        sample_b.col(j) = points_b.col(sample[static_cast<std::size_t>(j)]);
      }
      const std::optional<Similarity> similarity = fit(sample_a, sample_b, with_scale);
      if (!similarity || !plausible(*similarity)) continue;
      std::vector<int> inliers = inliers_of(*similarity);
      if (inliers.size() > best_inliers.size()) {
        best_inliers = std::move(inliers);
        best_similarity = *similarity;
      }
    }
    for (int round = 0; round < 2 && best_inliers.size() >= 3; ++round) {
      Eigen::Matrix3Xd inlier_a(3, static_cast<Eigen::Index>(best_inliers.size())), inlier_b(3, static_cast<Eigen::Index>(best_inliers.size()));
      for (std::size_t i = 0; i < best_inliers.size(); ++i) {
        inlier_a.col(static_cast<Eigen::Index>(i)) = points_a.col(best_inliers[i]);
        inlier_b.col(static_cast<Eigen::Index>(i)) = points_b.col(best_inliers[i]);
      }
      const std::optional<Similarity> refined = fit(inlier_a, inlier_b, with_scale);
      if (!refined || !plausible(*refined)) break;
      std::vector<int> inliers = inliers_of(*refined);
      if (inliers.size() < best_inliers.size()) break;
      best_inliers = std::move(inliers);
      best_similarity = *refined;
    }
    const auto inlier_count = static_cast<int>(best_inliers.size());
    most_inliers = std::max(most_inliers, inlier_count);
    if (inlier_count < config_.min_inliers || inlier_count < config_.min_inlier_fraction * pairs) continue;
    if (best && best->inliers >= inlier_count) continue;
    double squared = 0.0;
    for (int i : best_inliers) squared += (best_similarity.apply(points_b.col(i)) - points_a.col(i)).squaredNorm();
    LandmarkMapLoop loop;
    loop.keyframe_a = k;
    loop.keyframe_b = keyframe_b;
    loop.scale = best_similarity.scale;
    loop.T_a_b = SE3(SO3::from_matrix(best_similarity.rotation), best_similarity.translation);
    loop.inliers = inlier_count;
    loop.pairs = pairs;
    loop.rmse = std::sqrt(squared / inlier_count);
    loop.place_score = candidate.score;
    best = loop;
  }
  if (!best) {
    return Error(fmt::format("keyframe {}: no candidate verified (most matched pairs {}, most inliers {}; {} and {} of them needed)", keyframe_b, most_pairs,
                             most_inliers, config_.min_inliers, config_.min_inlier_fraction));
  }
  return *best;
}

}  // namespace hanzo::fusion::vision
