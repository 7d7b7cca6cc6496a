#include "hanzo/fusion/vision/visual_loop_detector.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/vision/feature_matcher.hpp"
#include "pose_refinement.hpp"
#include "triangulation.hpp"

namespace hanzo::fusion::vision {
namespace {

constexpr double kDegree = M_PI / 180.0;
// PnP RANSAC: inlier threshold (pixels, at octave 0) and iterations.
constexpr double kPnpThresholdPx = 3.0;
constexpr int kPnpIterations = 200;
// The most the refinement may move the PnP pose: times the points' median depth, and radians.
constexpr double kMaxRefinement = 0.05;

}  // namespace

Status validate(const VisualLoopDetectorConfig& config) {
  HANZO_RETURN_IF_ERROR(with_context(validate(config.features), "features"));
  if (config.triangulation_neighbours < 1) return Error("VisualLoopDetectorConfig.triangulation_neighbours: must be at least 1", "triangulation_neighbours");
  if (config.min_views < 2 || config.min_views > 2 * config.triangulation_neighbours + 1) {
    return Error("VisualLoopDetectorConfig.min_views: must be at least 2 and at most 2 triangulation_neighbours + 1", "min_views");
  }
  if (config.min_place_gap < 2 * config.triangulation_neighbours + 1) {
    return Error("VisualLoopDetectorConfig.min_place_gap: must exceed twice triangulation_neighbours", "min_place_gap");
  }
  if (config.candidates < 1) return Error("VisualLoopDetectorConfig.candidates: must be at least 1", "candidates");
  if (config.min_inliers < 6) return Error("VisualLoopDetectorConfig.min_inliers: must be at least 6", "min_inliers");
  if (!(config.min_inlier_share >= 0.0 && config.min_inlier_share <= 1.0)) {
    return Error("VisualLoopDetectorConfig.min_inlier_share: must be in [0, 1]", "min_inlier_share");
  }
  if (!(config.min_parallax_degrees > 0.0 && config.min_parallax_degrees < 90.0)) {
    return Error("VisualLoopDetectorConfig.min_parallax_degrees: must be in (0, 90)", "min_parallax_degrees");
  }
  if (!(config.pixel_sigma > 0.0)) return Error("VisualLoopDetectorConfig.pixel_sigma: must be > 0", "pixel_sigma");
  if (!(config.translation_sigma > 0.0) || !(config.rotation_sigma > 0.0) || !(config.translation_sigma_per_metre >= 0.0) ||
      !(config.rotation_sigma_per_metre >= 0.0)) {
    return Error("VisualLoopDetectorConfig: translation_sigma and rotation_sigma must be > 0, their per-metre growth >= 0", "translation_sigma");
  }
  if (config.cooldown_places < 0) return Error("VisualLoopDetectorConfig.cooldown_places: must not be negative", "cooldown_places");
  return ok_status();
}

Result<VisualLoopDetector> VisualLoopDetector::create(const PinholeCamera& camera, VisualLoopDetectorConfig config) {
  HANZO_RETURN_IF_ERROR(validate(config));
  if (!(camera.fx > 0.0) || !(camera.fy > 0.0)) return Error(fmt::format("camera: focal lengths {} {} must be positive", camera.fx, camera.fy));
  std::shared_ptr<const Vocabulary> vocabulary = config.vocabulary;
  if (!vocabulary) {
    Result<Vocabulary> loaded = Vocabulary::load_default();
    if (!loaded) return loaded.error();
    vocabulary = std::make_shared<const Vocabulary>(std::move(loaded).value());
  }
  return VisualLoopDetector(camera, std::move(config), std::move(vocabulary));
}

VisualLoopDetector::VisualLoopDetector(const PinholeCamera& camera, VisualLoopDetectorConfig config, std::shared_ptr<const Vocabulary> vocabulary)
    : camera_(camera), config_(std::move(config)), extractor_(config_.features), vocabulary_(vocabulary), database_(std::move(vocabulary)) {}

double VisualLoopDetector::keypoint_sigma(const cv::KeyPoint& keypoint) const {
  return config_.pixel_sigma * std::pow(config_.features.scale_factor, keypoint.octave);
}

Result<std::optional<VisualLoop>> VisualLoopDetector::add(const cv::Mat& image, const SE3& T_odometry_camera, const StaticMask& static_mask) {
  if (image.empty()) return Error("visual loop detector: empty image");
  if (!T_odometry_camera.matrix().allFinite()) return Error("visual loop detector: the camera pose is not finite");
  Place place;
  HANZO_ASSIGN_OR_RETURN(place.features, extractor_.extract(image, static_mask.pixels));
  place.T_odometry_camera = T_odometry_camera;
  place.normalized.reserve(place.features.size());
  for (const cv::KeyPoint& keypoint : place.features.keypoints) place.normalized.push_back(camera_.unproject({keypoint.pt.x, keypoint.pt.y}));
  FeatureVector words_by_node;
  const BowVector bow = vocabulary_->transform(place.features.descriptors, &words_by_node);
  const bool kept = !covered(T_odometry_camera);
  const int current = kept ? database_.add(bow, std::move(words_by_node)) : size();
  if (kept) {
    places_.push_back(std::move(place));
    // The place `span` back now has all its neighbours: its points are triangulated, and the
    // place 2 span back, whose neighbours they were, keeps only its points from now on.
    const std::size_t newest = places_.size() - 1, span = static_cast<std::size_t>(config_.triangulation_neighbours);
    if (newest >= span) triangulate_points(newest - span);
    if (newest >= 2 * span) {
      Place& old = places_[newest - 2 * span];
      old.features = ImageFeatures();
      old.normalized = {};
    }
  } else {
    ++covered_places_;
  }
  const Place& offered = kept ? places_.back() : place;
  ++places_since_loop_;

  const int before = current - config_.min_place_gap + 1;
  if (before <= 0 || places_since_loop_ <= config_.cooldown_places || bow.empty()) return std::optional<VisualLoop>();
  // A candidate must resemble the new place more than its own recent places do.
  double min_score = 1.0;
  for (int recent = std::max(0, current - 3); recent < current; ++recent) min_score = std::min(min_score, Vocabulary::score(bow, database_.bow(recent)));
  for (const PlaceMatch& candidate : database_.query(bow, config_.candidates, before, std::max(min_score, 0.01))) {
    ++candidates_checked_;
    std::optional<VisualLoop> loop = verify(candidate.entry, offered);
    if (!loop) continue;
    loop->current = kept ? current : -1;
    loop->score = candidate.score;
    ++loops_;
    places_since_loop_ = 0;
    logger()->debug("visual loop detector: place {} closes a loop with place {} (score {:.3f}, {} of {} matches)", current, candidate.entry,
                    candidate.score, loop->inliers, loop->matches);
    return loop;
  }
  return std::optional<VisualLoop>();
}

bool VisualLoopDetector::covered(const SE3& T_odometry_camera) const {
  if (!(config_.covered_place_distance > 0)) return false;
  const int older = size() - config_.min_place_gap;
  for (int i = 0; i < older; ++i) {
    const SE3 between = places_[static_cast<std::size_t>(i)].T_odometry_camera.inverse() * T_odometry_camera;
    if (between.translation().norm() < config_.covered_place_distance && between.rotation().log().norm() < config_.covered_place_angle) return true;
  }
  return false;
}

void VisualLoopDetector::triangulate_points(std::size_t index) {
  Place& middle = places_[index];
  if (middle.features.size() == 0) return;
  // Views of the place's keypoints in its neighbours, with the neighbour's pose in the place's
  // camera frame.
  struct View {
    const Place* place;
    SE3 T_view_middle;
    std::vector<int> keypoint_of;  // per middle keypoint, -1 when not matched
  };
  std::vector<View> views;
  const std::size_t span = static_cast<std::size_t>(config_.triangulation_neighbours);
  for (std::size_t neighbour = index >= span ? index - span : 0; neighbour <= index + span && neighbour < places_.size(); ++neighbour) {
    if (neighbour == index || places_[neighbour].features.size() == 0) continue;
    View view{&places_[neighbour], places_[neighbour].T_odometry_camera.inverse() * middle.T_odometry_camera,
              std::vector<int>(middle.features.size(), -1)};
    for (const FeatureMatch& match : match_descriptors(middle.features.descriptors, view.place->features.descriptors)) {
      view.keypoint_of[static_cast<std::size_t>(match.query)] = match.train;
    }
    views.push_back(std::move(view));
  }
  const double min_parallax = config_.min_parallax_degrees * kDegree;
  std::vector<SE3> poses;
  std::vector<Eigen::Vector2d> normalized;
  std::vector<PoseObservation> seen;
  std::vector<int> kept;
  for (std::size_t k = 0; k < middle.features.size(); ++k) {
    if (!middle.normalized[k]) continue;
    const cv::KeyPoint& keypoint = middle.features.keypoints[k];
    poses = {SE3()};
    normalized = {*middle.normalized[k]};
    seen = {PoseObservation{Eigen::Vector3d::Zero(), {keypoint.pt.x, keypoint.pt.y}, keypoint_sigma(keypoint)}};
    for (const View& view : views) {
      const int other = view.keypoint_of[k];
      if (other < 0 || !view.place->normalized[static_cast<std::size_t>(other)]) continue;
      const cv::KeyPoint& other_keypoint = view.place->features.keypoints[static_cast<std::size_t>(other)];
      poses.push_back(view.T_view_middle);
      normalized.push_back(*view.place->normalized[static_cast<std::size_t>(other)]);
      seen.push_back({Eigen::Vector3d::Zero(), {other_keypoint.pt.x, other_keypoint.pt.y}, keypoint_sigma(other_keypoint)});
    }
    if (static_cast<int>(poses.size()) < config_.min_views) continue;
    const std::optional<Eigen::Vector3d> point = triangulate_views(poses, normalized);
    if (!point) continue;
    bool consistent = true;
    double parallax = 0.0;
    for (std::size_t v = 0; v < poses.size() && consistent; ++v) {
      seen[v].point_world = *point;
      consistent = poses[v].act(*point).z() > 0.0 && reprojection_chi2(poses[v], seen[v], camera_) <= kChi2Pixel95;
      if (v > 0) parallax = std::max(parallax, triangulation_angle(SE3(), poses[v], *point));
    }
    if (!consistent || parallax < min_parallax) continue;
    kept.push_back(static_cast<int>(k));
    middle.points.push_back(*point);
  }
  middle.point_descriptors = cv::Mat(static_cast<int>(kept.size()), middle.features.descriptors.cols, CV_8UC1);
  for (std::size_t i = 0; i < kept.size(); ++i) middle.features.descriptors.row(kept[i]).copyTo(middle.point_descriptors.row(static_cast<int>(i)));
}

std::optional<VisualLoop> VisualLoopDetector::verify(int candidate, const Place& current) const {
  // The candidate's points and its neighbours' (in the candidate's camera frame through the
  // odometry's short relative poses): more of the scene than one image's.
  const Place& place = places_.at(static_cast<std::size_t>(candidate));
  std::vector<Eigen::Vector3d> candidate_points;
  std::vector<cv::Mat> descriptor_blocks;
  for (int neighbour = std::max(0, candidate - 1); neighbour <= candidate + 1 && neighbour < size(); ++neighbour) {
    const Place& other = places_[static_cast<std::size_t>(neighbour)];
    if (other.points.empty()) continue;
    const SE3 T_place_other = place.T_odometry_camera.inverse() * other.T_odometry_camera;
    for (const Eigen::Vector3d& point : other.points) candidate_points.push_back(T_place_other.act(point));
    descriptor_blocks.push_back(other.point_descriptors);
  }
  if (static_cast<int>(candidate_points.size()) < config_.min_inliers) return std::nullopt;
  cv::Mat candidate_descriptors;
  cv::vconcat(descriptor_blocks, candidate_descriptors);
  const std::vector<FeatureMatch> matches = match_descriptors(candidate_descriptors, current.features.descriptors);
  std::vector<cv::Point3d> points;
  std::vector<cv::Point2d> normalized;
  std::vector<PoseObservation> observations;
  for (const FeatureMatch& match : matches) {
    const auto& x = current.normalized[static_cast<std::size_t>(match.train)];
    if (!x) continue;
    const Eigen::Vector3d& point = candidate_points[static_cast<std::size_t>(match.query)];
    const cv::KeyPoint& keypoint = current.features.keypoints[static_cast<std::size_t>(match.train)];
    points.emplace_back(point.x(), point.y(), point.z());
    normalized.emplace_back(x->x(), x->y());
    observations.push_back({point, {keypoint.pt.x, keypoint.pt.y}, keypoint_sigma(keypoint)});
  }
  if (static_cast<int>(observations.size()) < config_.min_inliers) return std::nullopt;
  const std::optional<PnpSolution> pnp = solve_pnp_ransac(points, normalized, kPnpThresholdPx / camera_.fx, kPnpIterations);
  if (!pnp || static_cast<int>(pnp->inliers.size()) < config_.min_inliers) return std::nullopt;
  const PoseRefinement refined = refine_pose(pnp->T_camera_world, observations, camera_);
  if (refined.inliers < config_.min_inliers || refined.inliers < config_.min_inlier_share * static_cast<double>(observations.size())) {
    return std::nullopt;
  }
  std::vector<double> depths;
  for (std::size_t i = 0; i < observations.size(); ++i) {
    if (refined.inlier[i]) depths.push_back(refined.T_camera_world.act(observations[i].point_world).z());
  }
  std::nth_element(depths.begin(), depths.begin() + static_cast<std::ptrdiff_t>(depths.size() / 2), depths.end());
  const SE3 refinement = pnp->T_camera_world * refined.T_camera_world.inverse();
  if (refinement.translation().norm() > kMaxRefinement * depths[depths.size() / 2] || refinement.rotation().log().norm() > kMaxRefinement) {
    return std::nullopt;
  }
  VisualLoop loop;
  loop.place = candidate;
  loop.T_place_current = refined.T_camera_world.inverse();
  loop.inliers = refined.inliers;
  loop.matches = static_cast<int>(observations.size());
  const double apart = loop.T_place_current.translation().norm();
  const double translation_sigma = config_.translation_sigma + config_.translation_sigma_per_metre * apart;
  const double rotation_sigma = config_.rotation_sigma + config_.rotation_sigma_per_metre * apart;
  loop.covariance.diagonal() << Eigen::Vector3d::Constant(translation_sigma * translation_sigma), Eigen::Vector3d::Constant(rotation_sigma * rotation_sigma);
  return loop;
}

std::vector<Eigen::Vector3d> VisualLoopDetector::points(int place) const { return places_.at(static_cast<std::size_t>(place)).points; }

}  // namespace hanzo::fusion::vision
