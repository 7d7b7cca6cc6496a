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
  LandmarkPlaceIndexConfig places;
  places.vocabulary = config.vocabulary;
  places.place_model = config.place_model;
  places.learned_place_recognition = config.learned_place_recognition;
  Result<LandmarkPlaceIndex> index = LandmarkPlaceIndex::create(map, places);
  if (!index) return index.error();
  relocalizer.places_ = std::make_shared<const LandmarkPlaceIndex>(std::move(*index));
  relocalizer.descriptors_ = relocalizer.places_->descriptors();
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

Result<MapRelocalization> MapRelocalizer::relocalize(const cv::Mat& image) const {
  Result<ImageFeatures> extracted = extractor_->extract(image);
  if (!extracted) return extracted.error();
  const ImageFeatures& features = *extracted;
  if (features.size() < static_cast<std::size_t>(config_.min_inliers)) {
    return Error(fmt::format("relocalization: {} features in the image (< {})", features.size(), config_.min_inliers));
  }
  const std::vector<PlaceCandidate> ranked = places_->rank(features.descriptors, config_.candidates);
  const std::string& place_recognition = places_->method();

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
