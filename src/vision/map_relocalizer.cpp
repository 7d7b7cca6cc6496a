#include "hanzo/fusion/vision/map_relocalizer.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "hanzo/fusion/vision/feature_matcher.hpp"
#include "pose_refinement.hpp"
#include "projection_matching.hpp"

namespace hanzo::fusion::vision {

namespace {
// Learned descriptors: the largest Euclidean distance of unit rows matched (as the odometry's
// max_float_descriptor_distance) and the candidates' ratio test.
constexpr double kMaxFloatDistance = 1.0;
constexpr double kFloatRatio = 0.9;
}  // namespace

Result<MapRelocalizer> MapRelocalizer::create(msgs::VisualLandmarkLayer map, const PinholeCamera& camera, MapRelocalizerConfig config) {
  if (map.positions.empty() || map.keyframes.empty()) {
    return Error(fmt::format("visual landmark map: {} landmarks and {} keyframes (needs both)", map.positions.size(), map.keyframes.size()));
  }
  const bool orb_map = map.descriptor_type == "orb";
  if (orb_map && map.descriptors.size() != map.positions.size()) {
    return Error(fmt::format("visual landmark map: {} descriptors for {} landmarks", map.descriptors.size(), map.positions.size()));
  }
  if (!orb_map && (map.float_descriptor_size == 0 || map.float_descriptors.size() != map.float_descriptor_size * map.positions.size())) {
    return Error(fmt::format("visual landmark map: {} float descriptors of {} for {} landmarks", map.float_descriptors.size(), map.float_descriptor_size,
                             map.positions.size()));
  }
  if (!(camera.fx > 0.0 && camera.fy > 0.0)) return Error(fmt::format("camera: focal lengths must be positive (fx {}, fy {})", camera.fx, camera.fy));
  if (config.min_inliers < 6 || config.candidates < 1 || config.neighbour_keyframes < 0 || !(config.pixel_sigma > 0.0) || !(config.max_landmark_std >= 0.0) ||
      !(config.projection_search_radius_px > 0.0)) {
    return Error("MapRelocalizerConfig: min_inliers >= 6, candidates >= 1, neighbour_keyframes >= 0, pixel_sigma > 0, max_landmark_std >= 0 and projection_search_radius_px > 0 are required");
  }
  if (!map.position_std.empty() && map.position_std.size() != map.positions.size()) {
    return Error(fmt::format("visual landmark map: {} uncertainties for {} landmarks", map.position_std.size(), map.positions.size()));
  }
  MapRelocalizer relocalizer;
  relocalizer.extractor_ = config.extractor;
  if (!relocalizer.extractor_) {
    if (Status features = validate(config.features); !features) return features.error();
    relocalizer.extractor_ = std::make_shared<const OrbFeatureExtractor>(config.features);
  }
  const auto* orb = dynamic_cast<const OrbFeatureExtractor*>(relocalizer.extractor_.get());
  relocalizer.scale_factor_ = orb != nullptr ? orb->config().scale_factor : 1.0;
  if (relocalizer.extractor_->name() != map.descriptor_type) {
    return Error(fmt::format("visual landmark map: its landmarks carry {} descriptors, the image's features are {}'s (relocalize with the map's features)",
                             map.descriptor_type, relocalizer.extractor_->name()));
  }
  for (const msgs::VisualKeyframe& keyframe : map.keyframes) {
    for (uint32_t landmark : keyframe.landmarks) {
      if (landmark >= map.positions.size()) return Error(fmt::format("visual landmark map: a keyframe sees landmark {} of {}", landmark, map.positions.size()));
    }
  }
  const auto landmark_count = static_cast<int>(map.positions.size());
  if (orb_map) {
    relocalizer.descriptors_ = cv::Mat(landmark_count, 32, CV_8UC1);
    for (std::size_t i = 0; i < map.descriptors.size(); ++i) std::copy(map.descriptors[i].begin(), map.descriptors[i].end(), relocalizer.descriptors_.ptr<uint8_t>(static_cast<int>(i)));
  } else {
    relocalizer.descriptors_ = cv::Mat(landmark_count, static_cast<int>(map.float_descriptor_size), CV_32FC1);
    std::copy(map.float_descriptors.begin(), map.float_descriptors.end(), relocalizer.descriptors_.ptr<float>(0));
  }
  const auto keyframe_descriptors = [&](const msgs::VisualKeyframe& keyframe) {
    cv::Mat seen;
    for (uint32_t landmark : keyframe.landmarks) seen.push_back(relocalizer.descriptors_.row(static_cast<int>(landmark)));
    return seen;
  };
  if (orb_map) {
    relocalizer.vocabulary_ = config.vocabulary;
    if (!relocalizer.vocabulary_) {
      Result<Vocabulary> loaded = Vocabulary::load_default();
      if (!loaded) return loaded.error();
      relocalizer.vocabulary_ = std::make_shared<const Vocabulary>(std::move(*loaded));
    }
    for (const msgs::VisualKeyframe& keyframe : map.keyframes) relocalizer.keyframe_words_.push_back(relocalizer.vocabulary_->transform(keyframe_descriptors(keyframe)));
  } else {
    relocalizer.place_model_ = config.learned_place_recognition ? config.place_model : nullptr;
    if (!relocalizer.place_model_ && config.learned_place_recognition) {
      if (Result<VladModel> loaded = VladModel::load_default(map.descriptor_type)) {
        relocalizer.place_model_ = std::make_shared<const VladModel>(std::move(*loaded));
      } else {
        spdlog::info("relocalization: no VLAD model for {} ({}); candidate keyframes by matched landmarks", map.descriptor_type, loaded.error().message);
      }
    }
    if (relocalizer.place_model_ && relocalizer.place_model_->extractor_name() != map.descriptor_type) {
      return Error(fmt::format("MapRelocalizerConfig.place_model: trained on {} descriptors, the map's are {}", relocalizer.place_model_->extractor_name(),
                               map.descriptor_type));
    }
    if (relocalizer.place_model_) {
      for (const msgs::VisualKeyframe& keyframe : map.keyframes) {
        Result<Eigen::VectorXf> described = relocalizer.place_model_->describe(keyframe_descriptors(keyframe));
        if (!described) return Error("visual landmark map: " + described.error().message);
        relocalizer.keyframe_vlad_.push_back(std::move(*described));
      }
    }
  }
  relocalizer.map_ = std::move(map);
  relocalizer.camera_ = camera;
  relocalizer.config_ = std::move(config);
  return relocalizer;
}

bool MapRelocalizer::usable(uint32_t landmark) const {
  return config_.max_landmark_std <= 0.0 || map_.position_std.empty() || map_.position_std[landmark] <= config_.max_landmark_std;
}

PoseRefinement MapRelocalizer::refine_by_projection(const SE3& T_camera_world, const std::vector<ProjectedLandmark>& landmarks,
                                                    const ImageFeatures& features, const KeypointGrid& grid, double radius_px) const {
  ProjectionSearch search;
  search.radius_px = radius_px;
  search.scale_factor = scale_factor_;
  search.ratio = 0.8;
  search.max_descriptor_distance = descriptor_distance_limit(descriptors_, 64, kMaxFloatDistance);
  std::vector<PoseObservation> observations;
  for (const auto& [keypoint_index, landmark] : match_by_projection(landmarks, features, grid, camera_, T_camera_world, search)) {
    const cv::KeyPoint& keypoint = features.keypoints[static_cast<std::size_t>(keypoint_index)];
    observations.push_back({map_.positions[static_cast<std::size_t>(landmark)].cast<double>(), {keypoint.pt.x, keypoint.pt.y},
                            config_.pixel_sigma * std::pow(scale_factor_, keypoint.octave)});
  }
  if (observations.size() < 6) return {T_camera_world, {}, 0};
  return refine_pose(T_camera_world, observations, camera_);
}

std::vector<std::pair<double, int>> MapRelocalizer::rank_keyframes(const ImageFeatures& features) const {
  std::vector<std::pair<double, int>> ranked;
  if (binary()) {
    const BowVector words = vocabulary_->transform(features.descriptors);
    for (std::size_t k = 0; k < keyframe_words_.size(); ++k) ranked.emplace_back(Vocabulary::score(words, keyframe_words_[k]), static_cast<int>(k));
  } else if (place_model_) {
    const Result<Eigen::VectorXf> query = place_model_->describe(features.descriptors);
    if (!query) return {};
    for (std::size_t k = 0; k < keyframe_vlad_.size(); ++k) ranked.emplace_back(VladModel::similarity(*query, keyframe_vlad_[k]), static_cast<int>(k));
  } else {
    // Each keyframe scores the share of its landmarks that the image's descriptors match.
    DescriptorMatcherConfig matcher;
    matcher.float_ratio = kFloatRatio;
    matcher.max_float_distance = kMaxFloatDistance;
    std::vector<char> matched(map_.positions.size(), 0);
    for (const FeatureMatch& match : match_descriptors(descriptors_, features.descriptors, matcher)) matched[static_cast<std::size_t>(match.query)] = 1;
    for (std::size_t k = 0; k < map_.keyframes.size(); ++k) {
      const std::vector<uint32_t>& seen = map_.keyframes[k].landmarks;
      const auto hits = std::count_if(seen.begin(), seen.end(), [&](uint32_t landmark) { return matched[landmark] != 0; });
      ranked.emplace_back(seen.empty() ? 0.0 : static_cast<double>(hits) / static_cast<double>(seen.size()), static_cast<int>(k));
    }
  }
  std::sort(ranked.begin(), ranked.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  ranked.resize(std::min<std::size_t>(ranked.size(), static_cast<std::size_t>(config_.candidates)));
  return ranked;
}

Result<MapRelocalization> MapRelocalizer::relocalize(const cv::Mat& image) const {
  Result<ImageFeatures> extracted = extractor_->extract(image);
  if (!extracted) return extracted.error();
  const ImageFeatures& features = *extracted;
  if (features.size() < static_cast<std::size_t>(config_.min_inliers)) {
    return Error(fmt::format("relocalization: {} features in the image (< {})", features.size(), config_.min_inliers));
  }
  const std::vector<std::pair<double, int>> ranked = rank_keyframes(features);
  const std::string place_recognition = binary() ? "bow" : place_model_ ? "learned" : "matches";

  std::vector<Eigen::Vector2d> normalized;
  for (const cv::KeyPoint& keypoint : features.keypoints) {
    normalized.push_back(camera_.unproject({keypoint.pt.x, keypoint.pt.y}).value_or(Eigen::Vector2d::Constant(std::nan(""))));
  }
  const KeypointGrid grid(features.keypoints, features.image_size, 32);
  std::vector<ProjectedLandmark> usable_landmarks;  // what matching by projection looks for
  for (std::size_t i = 0; i < map_.positions.size(); ++i) {
    if (usable(static_cast<uint32_t>(i))) {
      usable_landmarks.push_back({map_.positions[i].cast<double>(), descriptors_.row(static_cast<int>(i)), -1, static_cast<int>(i)});
    }
  }
  int best_inliers = 0;
  std::optional<MapRelocalization> best;  // the candidate whose pose explains the most landmarks
  std::vector<std::pair<SE3, int>> placements;  // every candidate's refined T_camera_world and its inliers
  for (const auto& [score, candidate] : ranked) {
    // The landmarks of the candidate and its neighbours.
    std::vector<uint32_t> landmarks;
    const int first = std::max(0, candidate - config_.neighbour_keyframes);
    const int last = std::min(static_cast<int>(map_.keyframes.size()) - 1, candidate + config_.neighbour_keyframes);
    for (int k = first; k <= last; ++k) {
      for (uint32_t landmark : map_.keyframes[static_cast<std::size_t>(k)].landmarks) {
        if (usable(landmark)) landmarks.push_back(landmark);
      }
    }
    std::sort(landmarks.begin(), landmarks.end());
    landmarks.erase(std::unique(landmarks.begin(), landmarks.end()), landmarks.end());
    if (static_cast<int>(landmarks.size()) < config_.min_inliers) continue;
    cv::Mat candidate_descriptors;
    for (uint32_t landmark : landmarks) candidate_descriptors.push_back(descriptors_.row(static_cast<int>(landmark)));
    DescriptorMatcherConfig matcher;
    matcher.ratio = 0.75;
    matcher.max_distance = 50;
    matcher.float_ratio = kFloatRatio;
    matcher.max_float_distance = kMaxFloatDistance;
    std::vector<cv::Point3d> object_points;
    std::vector<cv::Point2d> image_points;
    std::vector<PoseObservation> observations;
    for (const FeatureMatch& match : match_descriptors(candidate_descriptors, features.descriptors, matcher)) {
      const auto k = static_cast<std::size_t>(match.train);
      if (!std::isfinite(normalized[k].x())) continue;
      const Eigen::Vector3d p = map_.positions[landmarks[static_cast<std::size_t>(match.query)]].cast<double>();
      object_points.emplace_back(p.x(), p.y(), p.z());
      image_points.emplace_back(normalized[k].x(), normalized[k].y());
      const cv::KeyPoint& keypoint = features.keypoints[k];
      observations.push_back({p, {keypoint.pt.x, keypoint.pt.y}, config_.pixel_sigma * std::pow(scale_factor_, keypoint.octave)});
    }
    if (static_cast<int>(object_points.size()) < config_.min_inliers) continue;
    const std::optional<PnpSolution> solved = solve_pnp_ransac(object_points, image_points, 2.0 * config_.pixel_sigma / camera_.fx, 500);
    if (!solved || static_cast<int>(solved->inliers.size()) < config_.min_inliers) {
      best_inliers = std::max(best_inliers, solved ? static_cast<int>(solved->inliers.size()) : 0);
      continue;
    }
    // Refined on the PnP inliers: with many wrong matches among all, Gauss-Newton from the PnP
    // pose can be pulled away before the outlier rounds drop them.
    std::vector<PoseObservation> inlier_observations;
    for (const int inlier : solved->inliers) inlier_observations.push_back(observations[static_cast<std::size_t>(inlier)]);
    PoseRefinement refined = refine_pose(solved->T_camera_world, inlier_observations, camera_);
    best_inliers = std::max(best_inliers, refined.inliers);
    if (refined.inliers < config_.min_inliers) continue;
    // Every map landmark the pose brings into view, matched by projection, then the pose refined
    // on all of them: a first radius for the PnP pose, a tighter one for the refined pose.
    for (const double radius : {config_.projection_search_radius_px, config_.projection_search_radius_px / 2.0}) {
      const PoseRefinement guided = refine_by_projection(refined.T_camera_world, usable_landmarks, features, grid, radius);
      if (guided.inliers < refined.inliers) break;
      refined = guided;
    }
    placements.push_back({refined.T_camera_world, refined.inliers});
    if (!best || refined.inliers > best->inliers) best = MapRelocalization{refined.T_camera_world.inverse(), refined.inliers, candidate, score, place_recognition};
  }
  if (best) {
    // Step 4: another candidate's pose explains the image about as well.
    if (config_.ambiguity_ratio > 0.0 && config_.ambiguity_ratio <= 1.0) {
      for (const auto& [other, inliers] : placements) {
        const SE3 T_world_other = other.inverse();
        const double distance = (T_world_other.translation() - best->T_world_camera.translation()).norm();
        const double angle = (best->T_world_camera.rotation().inverse() * T_world_other.rotation()).angle();
        if ((distance < config_.ambiguity_distance_m && angle < config_.ambiguity_angle_deg * M_PI / 180.0) || inliers < config_.ambiguity_ratio * best->inliers) {
          continue;
        }
        return Error(fmt::format("relocalization: ambiguous: two poses {:.2f} m / {:.1f} deg apart explain {} and {} landmarks", distance,
                                 angle * 180.0 / M_PI, best->inliers, inliers));
      }
    }
    return *best;
  }
  return Error(fmt::format("relocalization: no pose with {} inliers among the {} most similar keyframes (best {})", config_.min_inliers, ranked.size(), best_inliers));
}

}  // namespace hanzo::fusion::vision
