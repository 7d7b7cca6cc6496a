#include "hanzo/fusion/vision/visual_odometry.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <future>
#include <limits>
#include <numeric>
#include <set>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/vision/bundle_adjustment.hpp"
#include "hanzo/fusion/vision/feature_matcher.hpp"
#include "hanzo/fusion/vision/place_database.hpp"
#include "hanzo/fusion/vision/vlad.hpp"
#include "pose_refinement.hpp"
#include "projection_matching.hpp"
#include "similarity_pose_graph.hpp"
#include "triangulation.hpp"

namespace hanzo::fusion::vision {
namespace {

constexpr double kDegree = M_PI / 180.0;

// Features of one image with their undistorted normalized coordinates (NaN where the camera
// model cannot invert the keypoint) and the landmark each keypoint observes (-1: none).
struct Frame {
  double time = 0.0;
  ImageFeatures features;
  std::vector<Eigen::Vector2d> normalized;
  std::vector<int> landmark;
  SE3 T_world_camera;
  // Stereo: the right image (kept until the frame's keyframe decision), its features, and the
  // right keypoint matched to each left keypoint (-1: none).
  cv::Mat right_image;
  ImageFeatures right_features;
  std::vector<int> right_keypoint;
};

struct Keyframe {
  int id = 0;
  Frame frame;
  bool starts_map = false;  // a stereo map restart: its pose was predicted, not tracked
};

struct Landmark {
  Eigen::Vector3d position;
  cv::Mat descriptor;  // one row (the keypoints' type), of the latest observation
  int octave = 0;      // of the latest observation
  std::vector<std::pair<int, int>> observations;  // (keyframe id, keypoint)
  int created_at = 0;  // keyframe id that created it
};

// A tracked frame: its pose relative to its reference keyframe.
struct FrameRecord {
  double time = 0.0;
  int keyframe = 0;
  SE3 T_keyframe_camera;
};

bool has_normalized(const Frame& frame, std::size_t keypoint) { return std::isfinite(frame.normalized[keypoint].x()); }

Eigen::Vector2d pixel_of(const Frame& frame, std::size_t keypoint) {
  const cv::Point2f& point = frame.features.keypoints[keypoint].pt;
  return {point.x, point.y};
}

Eigen::Vector2d right_pixel_of(const Frame& frame, std::size_t keypoint) {
  const cv::Point2f& point = frame.right_features.keypoints[static_cast<std::size_t>(frame.right_keypoint[keypoint])].pt;
  return {point.x, point.y};
}

// What the standstill test keeps of a frame: its keypoints, descriptors, landmarks and pose.
Frame anchor_of(const Frame& frame) {
  Frame anchor;
  anchor.time = frame.time;
  anchor.features = frame.features;
  anchor.landmark = frame.landmark;
  anchor.T_world_camera = frame.T_world_camera;
  return anchor;
}

bool has_right(const Frame& frame, std::size_t keypoint) { return !frame.right_keypoint.empty() && frame.right_keypoint[keypoint] >= 0; }

// The default vocabulary, loaded once per process; null (logged) when it cannot be read.
std::shared_ptr<const Vocabulary> default_vocabulary() {
  static const std::shared_ptr<const Vocabulary> vocabulary = []() -> std::shared_ptr<const Vocabulary> {
    Result<Vocabulary> loaded = Vocabulary::load_default();
    if (!loaded) {
      logger()->warn("visual odometry: loop closure off: {}", loaded.error().message);
      return nullptr;
    }
    return std::make_shared<const Vocabulary>(std::move(*loaded));
  }();
  return vocabulary;
}

}  // namespace

const char* to_string(TrackingState state) {
  switch (state) {
    case TrackingState::kInitializing: return "initializing";
    case TrackingState::kTracking: return "tracking";
    case TrackingState::kLost: return "lost";
  }
  return "unknown";
}

Status validate(const VisualOdometryConfig& config) {
  if (Status features = validate(config.features); !features) return features;
  auto positive = [](double value) { return std::isfinite(value) && value > 0.0; };
  if (config.min_initialization_inliers < 8) return Error("VisualOdometryConfig.min_initialization_inliers: must be at least 8", "min_initialization_inliers");
  if (!positive(config.min_initialization_parallax_deg)) return Error("VisualOdometryConfig.min_initialization_parallax_deg: must be positive", "min_initialization_parallax_deg");
  if (!positive(config.projection_search_radius_px)) return Error("VisualOdometryConfig.projection_search_radius_px: must be positive", "projection_search_radius_px");
  if (config.max_descriptor_distance < 1 || config.max_descriptor_distance > 256) return Error("VisualOdometryConfig.max_descriptor_distance: must be in 1..256", "max_descriptor_distance");
  if (!(config.max_float_descriptor_distance > 0.0 && config.max_float_descriptor_distance <= 2.0)) {
    return Error("VisualOdometryConfig.max_float_descriptor_distance: must be in (0, 2]", "max_float_descriptor_distance");
  }
  if (config.min_tracked_landmarks < 6) return Error("VisualOdometryConfig.min_tracked_landmarks: must be at least 6", "min_tracked_landmarks");
  if (!positive(config.pixel_sigma)) return Error("VisualOdometryConfig.pixel_sigma: must be positive", "pixel_sigma");
  if (!(config.keyframe_tracked_ratio > 0.0 && config.keyframe_tracked_ratio <= 1.0)) return Error("VisualOdometryConfig.keyframe_tracked_ratio: must be in (0, 1]", "keyframe_tracked_ratio");
  if (config.max_frames_between_keyframes < 1) return Error("VisualOdometryConfig.max_frames_between_keyframes: must be at least 1", "max_frames_between_keyframes");
  if (!positive(config.min_triangulation_angle_deg)) return Error("VisualOdometryConfig.min_triangulation_angle_deg: must be positive", "min_triangulation_angle_deg");
  if (config.triangulation_keyframes < 1) return Error("VisualOdometryConfig.triangulation_keyframes: must be at least 1", "triangulation_keyframes");
  if (!(config.min_triangulation_baseline_share >= 0.0)) return Error("VisualOdometryConfig.min_triangulation_baseline_share: must not be negative", "min_triangulation_baseline_share");
  if (config.window_keyframes < 2) return Error("VisualOdometryConfig.window_keyframes: must be at least 2", "window_keyframes");
  if (!(config.standstill_pixels >= 0.0)) return Error("VisualOdometryConfig.standstill_pixels: must not be negative", "standstill_pixels");
  if (!(config.max_stereo_depth_baselines > 0.0)) return Error("VisualOdometryConfig.max_stereo_depth_baselines: must be positive", "max_stereo_depth_baselines");
  if (!(config.moving_object_pixels > 0.0)) return Error("VisualOdometryConfig.moving_object_pixels: must be positive", "moving_object_pixels");
  if (!(config.standstill_share > 0.0 && config.standstill_share <= 1.0)) return Error("VisualOdometryConfig.standstill_share: must be in (0, 1]", "standstill_share");
  if (!(config.standstill_max_translation > 0.0)) return Error("VisualOdometryConfig.standstill_max_translation: must be positive", "standstill_max_translation");
  if (config.bundle_adjustment_iterations < 0) return Error("VisualOdometryConfig.bundle_adjustment_iterations: must not be negative", "bundle_adjustment_iterations");
  if (config.loop_closure && config.loop_min_keyframe_gap < config.window_keyframes) return Error("VisualOdometryConfig.loop_min_keyframe_gap: must be at least window_keyframes", "loop_min_keyframe_gap");
  if (config.loop_min_inliers < 3) return Error("VisualOdometryConfig.loop_min_inliers: must be at least 3", "loop_min_inliers");
  if (!(config.putative_filter_threshold > 0.0 && config.putative_filter_threshold < 1.0)) {
    return Error("VisualOdometryConfig.putative_filter_threshold: must be in (0, 1)", "putative_filter_threshold");
  }
  if (config.loop_cooldown_keyframes < 0) return Error("VisualOdometryConfig.loop_cooldown_keyframes: must not be negative", "loop_cooldown_keyframes");
  return ok_status();
}

struct VisualOdometry::State {
  PinholeCamera camera;
  cv::Size image_size;
  VisualOdometryConfig config;
  std::shared_ptr<const FeatureExtractor> extractor;
  // Stereo: the right camera and where it sits in the left camera's frame.
  std::optional<PinholeCamera> right_camera;
  SE3 T_left_right;
  bool rgbd = false;  // the "right" keypoints come from a depth image through a virtual camera

  std::map<int, Keyframe> keyframes;
  std::map<int, Landmark> landmarks;
  int next_keyframe_id = 0;
  int next_landmark_id = 0;
  std::vector<FrameRecord> frames;
  VisualOdometrySummary counts;

  std::optional<Frame> reference;     // initialization's first view
  std::optional<Frame> still_anchor;  // the last frame tracked in motion: its features,
  FrameRecord still_anchor_record;    // and its pose relative to its keyframe
  bool initialized = false;
  bool lost = false;
  std::optional<double> last_time;
  // Constant-velocity model: the last tracked pose and the body twist per second.
  double last_pose_time = 0.0;
  SE3 last_pose;
  SE3::Tangent velocity = SE3::Tangent::Zero();
  int frames_since_keyframe = 0;
  int last_keyframe_tracked = 0;

  // Loop closure: the keyframes' bags of words or VLAD vectors (entry i is keyframe place_keyframe[i]).
  std::shared_ptr<const Vocabulary> vocabulary;
  std::optional<PlaceDatabase> places;
  std::shared_ptr<const VladModel> place_model;  // learned place recognition: one vector per keyframe
  std::vector<Eigen::VectorXf> place_vectors;
  std::vector<int> place_keyframe;
  std::vector<std::pair<int, int>> loops;  // (candidate, current) keyframes of closed loops
  int keyframes_since_loop = std::numeric_limits<int>::max() / 2;

  // scale_factor^octave for every pyramid level (looked up in the matchers' inner loops).
  std::vector<double> octave_scale;
  double sigma(int octave) const { return config.pixel_sigma * octave_scale[static_cast<std::size_t>(octave)]; }
  // The image's features, their extraction time added to `seconds`.
  Result<ImageFeatures> extract(const cv::Mat& image, double& seconds, const cv::Mat& mask = cv::Mat()) const {
    const auto start = std::chrono::steady_clock::now();
    Result<ImageFeatures> features = extractor->extract(image, mask);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return features;
  }
  // Extraction time of right images (stereo matching, which the local mapping runs while the
  // tracking thread extracts left images into counts.feature_seconds).
  double right_feature_seconds = 0.0;

  // Local mapping of the newest keyframe: running (local_mapping_thread) until joined. Only
  // the tracking thread starts and joins it; while it runs the tracking thread touches nothing
  // but the extractor, the frame checks and counts' per-frame fields.
  std::future<void> mapping;
  bool loop_closed_by_mapping = false;  // reported with the next frame
  void finish_mapping() {
    if (!mapping.valid()) return;
    const auto start = std::chrono::steady_clock::now();
    mapping.get();
    counts.mapping_wait_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  ~State() {
    if (mapping.valid()) mapping.wait();
  }

  // The largest descriptor distance of a match between descriptors like `descriptors`.
  int max_distance(const cv::Mat& descriptors) const {
    return descriptor_distance_limit(descriptors, config.max_descriptor_distance, config.max_float_descriptor_distance);
  }

  Frame make_frame(double time, ImageFeatures features) const {
    Frame frame;
    frame.time = time;
    frame.normalized.reserve(features.size());
    for (const cv::KeyPoint& keypoint : features.keypoints) {
      const std::optional<Eigen::Vector2d> normalized = camera.unproject({keypoint.pt.x, keypoint.pt.y});
      frame.normalized.push_back(normalized.value_or(Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN())));
    }
    frame.landmark.assign(features.size(), -1);
    frame.features = std::move(features);
    return frame;
  }

  // ---- map bookkeeping ----

  int add_landmark(const Eigen::Vector3d& position, const Keyframe& first, int keypoint1, Keyframe& second, int keypoint2) {
    const int id = next_landmark_id++;
    Landmark landmark;
    landmark.position = position;
    landmark.descriptor = second.frame.features.descriptors.row(keypoint2).clone();
    landmark.octave = second.frame.features.keypoints[static_cast<std::size_t>(keypoint2)].octave;
    landmark.observations = {{first.id, keypoint1}, {second.id, keypoint2}};
    landmark.created_at = second.id;
    landmarks.emplace(id, std::move(landmark));
    keyframes.at(first.id).frame.landmark[static_cast<std::size_t>(keypoint1)] = id;
    second.frame.landmark[static_cast<std::size_t>(keypoint2)] = id;
    return id;
  }

  void remove_observation(int landmark_id, int keyframe_id) {
    Landmark& landmark = landmarks.at(landmark_id);
    auto& observations = landmark.observations;
    for (auto it = observations.begin(); it != observations.end();) {
      if (it->first == keyframe_id) {
        keyframes.at(keyframe_id).frame.landmark[static_cast<std::size_t>(it->second)] = -1;
        it = observations.erase(it);
      } else {
        ++it;
      }
    }
  }

  void remove_landmark(int landmark_id) {
    for (const auto& [keyframe_id, keypoint] : landmarks.at(landmark_id).observations) {
      keyframes.at(keyframe_id).frame.landmark[static_cast<std::size_t>(keypoint)] = -1;
    }
    landmarks.erase(landmark_id);
  }

  std::vector<int> window() const {
    std::vector<int> ids;
    for (auto it = keyframes.rbegin(); it != keyframes.rend() && static_cast<int>(ids.size()) < config.window_keyframes; ++it) ids.push_back(it->first);
    std::reverse(ids.begin(), ids.end());
    return ids;
  }

  std::vector<int> local_landmarks() const {
    std::set<int> ids;
    for (int keyframe_id : window()) {
      for (int landmark_id : keyframes.at(keyframe_id).frame.landmark) {
        if (landmark_id >= 0) ids.insert(landmark_id);
      }
    }
    return {ids.begin(), ids.end()};
  }

  // Observations of a landmark (a stereo keyframe's right image counts as one more), over the
  // given keyframes only when `window` is given.
  int observation_count(const Landmark& landmark, const std::set<int>* window = nullptr) const {
    int count = 0;
    for (const auto& [keyframe_id, keypoint] : landmark.observations) {
      if (window != nullptr && !window->count(keyframe_id)) continue;
      count += 1 + has_right(keyframes.at(keyframe_id).frame, static_cast<std::size_t>(keypoint));
    }
    return count;
  }

  // ---- stereo ----

  // Right features of a frame and the right keypoint of each left one: the nearest descriptor
  // (ratio 0.8 against the runner-up: repeated texture along the epipolar line) among the right
  // keypoints within 2 sigma of the left
  // keypoint's epipolar line (from the rig's extrinsics) and one octave; each right keypoint
  // kept by the left keypoint it matches best.
  void match_stereo(Frame& frame) {
    frame.right_keypoint.assign(frame.features.size(), -1);
    if (rgbd) return match_depth(frame);
    Result<ImageFeatures> right = extract(frame.right_image, right_feature_seconds);
    frame.right_image.release();
    if (!right) return;
    frame.right_features = std::move(right).value();
    std::vector<Eigen::Vector2d> right_normalized;
    for (const cv::KeyPoint& keypoint : frame.right_features.keypoints) {
      right_normalized.push_back(right_camera->unproject({keypoint.pt.x, keypoint.pt.y}).value_or(Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN())));
    }
    const SE3 T_right_left = T_left_right.inverse();
    const Eigen::Matrix3d essential = SO3::hat(T_right_left.translation()) * T_right_left.rotation().matrix();  // x_r^T E x_l = 0
    std::vector<std::pair<int, int>> owner(frame.right_features.size(), {-1, std::numeric_limits<int>::max()});
    for (std::size_t k = 0; k < frame.features.size(); ++k) {
      if (!has_normalized(frame, k)) continue;
      const Eigen::Vector3d line = essential * frame.normalized[k].homogeneous();
      const double line_norm = line.head<2>().norm();
      if (line_norm < 1e-12) continue;
      const int octave = frame.features.keypoints[k].octave;
      NearestCandidates nearest;
      for (std::size_t r = 0; r < frame.right_features.size(); ++r) {
        const cv::KeyPoint& candidate = frame.right_features.keypoints[r];
        if (std::abs(candidate.octave - octave) > 1 || !std::isfinite(right_normalized[r].x())) continue;
        if (std::abs(right_normalized[r].homogeneous().dot(line)) / line_norm * right_camera->fx > 2.0 * sigma(candidate.octave)) continue;
        nearest.offer(static_cast<int>(r), descriptor_distance(frame.features.descriptors, static_cast<int>(k), frame.right_features.descriptors, static_cast<int>(r)));
      }
      if (!nearest.passes(0.8, max_distance(frame.features.descriptors))) continue;
      const int best_right = nearest.index, best = nearest.best;
      auto& slot = owner[static_cast<std::size_t>(best_right)];
      if (best < slot.second) slot = {static_cast<int>(k), best};
    }
    for (std::size_t r = 0; r < owner.size(); ++r) {
      if (owner[r].first >= 0) frame.right_keypoint[static_cast<std::size_t>(owner[r].first)] = static_cast<int>(r);
    }
  }

  // RGB-D (ORB-SLAM2's virtual stereo, Mur-Artal & Tardos 2017, sec. III-A): each keypoint
  // with a depth d becomes a right keypoint where its point d (x_n, y_n, 1) projects into a
  // virtual right camera T_left_right away (the same descriptor), so that the stereo code
  // (landmarks, bundle adjustment's right projections) uses the depth. A depth is used when the
  // pixels around the keypoint lie on one smooth surface with it: on a plane the inverse depth
  // is affine in the pixel, so the centre's is the mean of each opposite pair of neighbours'
  // (within 3 %); at a depth edge (foreground against background) it is not.
  void match_depth(Frame& frame) {
    const cv::Mat depth = frame.right_image;
    frame.right_image.release();
    const auto depth_at = [&depth](int row, int column) {
      const double value = depth.type() == CV_16UC1 ? depth.at<uint16_t>(row, column) * 1e-3 : static_cast<double>(depth.at<float>(row, column));
      return std::isfinite(value) && value > 0.0 ? value : 0.0;
    };
    constexpr double kSmooth = 0.03;
    const SE3 T_right_left = T_left_right.inverse();
    frame.right_features.descriptors = cv::Mat(0, frame.features.descriptors.cols, frame.features.descriptors.type());
    for (std::size_t k = 0; k < frame.features.size(); ++k) {
      if (!has_normalized(frame, k)) continue;
      const cv::KeyPoint& keypoint = frame.features.keypoints[k];
      const int row = static_cast<int>(std::lround(keypoint.pt.y)), column = static_cast<int>(std::lround(keypoint.pt.x));
      if (row < 1 || column < 1 || row + 1 >= depth.rows || column + 1 >= depth.cols) continue;
      const double d = depth_at(row, column);
      if (!(d > 0.0)) continue;
      bool smooth = true;
      for (const auto& [dr, dc] : {std::pair{0, 1}, {1, 0}, {1, 1}, {1, -1}}) {
        const double a = depth_at(row + dr, column + dc), b = depth_at(row - dr, column - dc);
        smooth = smooth && a > 0.0 && b > 0.0 && std::abs(0.5 * (1.0 / a + 1.0 / b) - 1.0 / d) <= kSmooth / d;
      }
      if (!smooth) continue;
      const std::optional<Eigen::Vector2d> right_pixel = right_camera->project(T_right_left.act(d * frame.normalized[k].homogeneous()));
      if (!right_pixel) continue;
      cv::KeyPoint right_keypoint = keypoint;
      right_keypoint.pt = cv::Point2f(static_cast<float>(right_pixel->x()), static_cast<float>(right_pixel->y()));
      frame.right_keypoint[k] = static_cast<int>(frame.right_features.keypoints.size());
      frame.right_features.keypoints.push_back(right_keypoint);
      frame.right_features.descriptors.push_back(frame.features.descriptors.row(static_cast<int>(k)));
    }
  }

  // The stereo point of a left keypoint (world frame at the frame's pose), when it lies in front
  // of both cameras, reprojects within the chi-square bound in both, and is nearer than
  // max_stereo_depth_baselines rig baselines (farther, its depth is mostly noise).
  std::optional<Eigen::Vector3d> stereo_point(const Frame& frame, std::size_t keypoint) const {
    if (!has_right(frame, keypoint)) return std::nullopt;
    const auto right = static_cast<std::size_t>(frame.right_keypoint[keypoint]);
    const std::optional<Eigen::Vector2d> right_normalized = right_camera->unproject(right_pixel_of(frame, keypoint));
    if (!right_normalized) return std::nullopt;
    const SE3 T_right_left = T_left_right.inverse();
    const std::optional<Eigen::Vector3d> point_left = triangulate(SE3(), frame.normalized[keypoint], T_right_left, *right_normalized);
    if (!point_left || point_left->z() <= 0.0 || point_left->z() > config.max_stereo_depth_baselines * T_left_right.translation().norm()) return std::nullopt;
    const PoseObservation left_observation{*point_left, pixel_of(frame, keypoint), sigma(frame.features.keypoints[keypoint].octave)};
    const PoseObservation right_observation{*point_left, right_pixel_of(frame, keypoint), sigma(frame.right_features.keypoints[right].octave)};
    if (reprojection_chi2(SE3(), left_observation, camera) > kChi2Pixel95 || reprojection_chi2(T_right_left, right_observation, *right_camera) > kChi2Pixel95) {
      return std::nullopt;
    }
    return frame.T_world_camera.act(*point_left);
  }

  // Landmarks from the stereo points of a keyframe's keypoints that have none yet.
  int add_stereo_landmarks(Keyframe& keyframe) {
    int created = 0;
    for (std::size_t k = 0; k < keyframe.frame.features.size(); ++k) {
      if (keyframe.frame.landmark[k] >= 0) continue;
      const std::optional<Eigen::Vector3d> point = stereo_point(keyframe.frame, k);
      if (!point) continue;
      const int id = next_landmark_id++;
      Landmark landmark;
      landmark.position = *point;
      landmark.descriptor = keyframe.frame.features.descriptors.row(static_cast<int>(k)).clone();
      landmark.octave = keyframe.frame.features.keypoints[k].octave;
      landmark.observations = {{keyframe.id, static_cast<int>(k)}};
      landmark.created_at = keyframe.id;
      landmarks.emplace(id, std::move(landmark));
      keyframe.frame.landmark[k] = id;
      ++created;
    }
    return created;
  }

  // A keyframe of the frame's stereo points, at its pose, that the next frames track against;
  // false (nothing changed) when it has too few.
  bool restart_from_stereo(Frame frame) {
    match_stereo(frame);
    int points = 0;
    for (std::size_t k = 0; k < frame.features.size(); ++k) points += frame.landmark[k] < 0 && stereo_point(frame, k).has_value();
    if (points < config.min_initialization_inliers) return false;
    const int id = next_keyframe_id++;
    Keyframe& keyframe = keyframes.emplace(id, Keyframe{id, std::move(frame), true}).first->second;
    add_stereo_landmarks(keyframe);
    frames.push_back({keyframe.frame.time, id, SE3()});
    last_pose = keyframe.frame.T_world_camera;
    last_pose_time = keyframe.frame.time;
    last_keyframe_tracked = points;
    frames_since_keyframe = 0;
    still_anchor = anchor_of(keyframe.frame);
    still_anchor_record = frames.back();
    ++counts.map_restarts;
    logger()->warn("visual odometry: tracking lost at {:.3f} s: map restarted from {} stereo points", keyframe.frame.time, points);
    return true;
  }

  // Stereo: the first frame with enough stereo points is the first keyframe (metric scale).
  VisualOdometryFrame initialize_stereo(Frame frame) {
    VisualOdometryFrame result;
    result.time = frame.time;
    result.state = TrackingState::kInitializing;
    match_stereo(frame);
    frame.T_world_camera = SE3();
    const int id = next_keyframe_id;
    Keyframe& keyframe = keyframes.emplace(id, Keyframe{id, std::move(frame)}).first->second;
    const int created = add_stereo_landmarks(keyframe);
    if (created < config.min_initialization_inliers) {
      for (int landmark_id : std::vector<int>(keyframe.frame.landmark.begin(), keyframe.frame.landmark.end())) {
        if (landmark_id >= 0) landmarks.erase(landmark_id);
      }
      keyframes.erase(id);
      result.reason = fmt::format("{} stereo points (< {})", created, config.min_initialization_inliers);
      return result;
    }
    ++next_keyframe_id;
    frames.push_back({keyframe.frame.time, id, SE3()});
    initialized = true;
    last_pose = SE3();
    last_pose_time = keyframe.frame.time;
    velocity.setZero();
    last_keyframe_tracked = created;
    still_anchor = anchor_of(keyframe.frame);
    still_anchor_record = frames.back();
    logger()->info("visual odometry: initialized from one stereo frame with {} landmarks", created);
    result.state = TrackingState::kTracking;
    result.tracked_landmarks = created;
    result.keyframe = true;
    return result;
  }

  // ---- initialization ----

  VisualOdometryFrame initialize(Frame frame) {
    VisualOdometryFrame result;
    result.time = frame.time;
    result.state = TrackingState::kInitializing;
    if (!reference || static_cast<int>(reference->features.size()) < config.min_initialization_inliers) {
      result.reason = fmt::format("first view: {} keypoints", frame.features.size());
      reference = std::move(frame);
      return result;
    }
    std::vector<FeatureMatch> putative;
    if (config.putative_filter) {
      DescriptorMatcherConfig mutual_only = descriptor_matcher();
      mutual_only.ratio = mutual_only.float_ratio = 1.0;
      putative = config.putative_filter->filter(match_descriptors(reference->features.descriptors, frame.features.descriptors, mutual_only),
                                                reference->features, frame.features, config.putative_filter_threshold);
    } else {
      putative = match_descriptors(reference->features.descriptors, frame.features.descriptors, descriptor_matcher());
    }
    std::vector<FeatureMatch> matches;
    for (const FeatureMatch& match : putative) {
      if (has_normalized(*reference, static_cast<std::size_t>(match.query)) && has_normalized(frame, static_cast<std::size_t>(match.train))) matches.push_back(match);
    }
    if (static_cast<int>(matches.size()) < config.min_initialization_inliers) {
      result.reason = fmt::format("{} matches with the first view (< {}): new first view", matches.size(), config.min_initialization_inliers);
      reference = std::move(frame);
      return result;
    }
    std::vector<cv::Point2d> points1, points2;
    for (const FeatureMatch& match : matches) {
      const Eigen::Vector2d& a = reference->normalized[static_cast<std::size_t>(match.query)];
      const Eigen::Vector2d& b = frame.normalized[static_cast<std::size_t>(match.train)];
      points1.emplace_back(a.x(), a.y());
      points2.emplace_back(b.x(), b.y());
    }
    cv::Mat inlier_mask;
    const double threshold = config.pixel_sigma / camera.fx;
    const cv::Mat essential = cv::findEssentialMat(points1, points2, cv::Mat::eye(3, 3, CV_64F), cv::RANSAC, 0.999, threshold, inlier_mask);
    if (essential.rows != 3 || essential.cols != 3) {
      result.reason = "no essential matrix from the matches";
      return result;
    }
    cv::Mat rotation, translation;
    cv::recoverPose(essential, points1, points2, cv::Mat::eye(3, 3, CV_64F), rotation, translation, inlier_mask);
    Eigen::Matrix3d R;
    Eigen::Vector3d t;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) R(r, c) = rotation.at<double>(r, c);
      t(r) = translation.at<double>(r);
    }
    const SE3 T_camera2_camera1(SO3::from_matrix(R), t.normalized());  // the first baseline is the unit of length
    struct Candidate {
      Eigen::Vector3d point;
      int keypoint1, keypoint2;
      double angle;
    };
    std::vector<Candidate> good;
    for (std::size_t i = 0; i < matches.size(); ++i) {
      if (inlier_mask.at<unsigned char>(static_cast<int>(i)) == 0) continue;
      const auto k1 = static_cast<std::size_t>(matches[i].query), k2 = static_cast<std::size_t>(matches[i].train);
      const std::optional<Eigen::Vector3d> point = triangulate(SE3(), reference->normalized[k1], T_camera2_camera1, frame.normalized[k2]);
      if (!point) continue;
      const PoseObservation in1{*point, pixel_of(*reference, k1), sigma(reference->features.keypoints[k1].octave)};
      const PoseObservation in2{*point, pixel_of(frame, k2), sigma(frame.features.keypoints[k2].octave)};
      if (reprojection_chi2(SE3(), in1, camera) > kChi2Pixel95 || reprojection_chi2(T_camera2_camera1, in2, camera) > kChi2Pixel95) continue;
      good.push_back({*point, matches[i].query, matches[i].train, triangulation_angle(SE3(), T_camera2_camera1, *point)});
    }
    if (static_cast<int>(good.size()) < config.min_initialization_inliers / 2) {
      result.reason = fmt::format("{} triangulated points (< {})", good.size(), config.min_initialization_inliers / 2);
      return result;
    }
    // Enough points seen from clearly different directions (ORB-SLAM's test: a median would
    // wait for the far points, which forward motion hardly moves).
    const auto wide = std::count_if(good.begin(), good.end(), [&](const Candidate& c) { return c.angle >= config.min_initialization_parallax_deg * kDegree; });
    if (wide < config.min_initialization_inliers / 2) {
      result.reason = fmt::format("{} points with parallax over {:.1f} deg (< {})", wide, config.min_initialization_parallax_deg, config.min_initialization_inliers / 2);
      return result;
    }
    // Two keyframes and the landmarks.
    Keyframe first{next_keyframe_id++, std::move(*reference)};
    first.frame.T_world_camera = SE3();
    frame.T_world_camera = T_camera2_camera1.inverse();
    Keyframe second{next_keyframe_id++, std::move(frame)};
    reference.reset();
    keyframes.emplace(first.id, std::move(first));
    Keyframe& first_stored = keyframes.begin()->second;
    Keyframe& second_stored = keyframes.emplace(second.id, std::move(second)).first->second;
    for (const Candidate& candidate : good) {
      if (candidate.angle < config.min_triangulation_angle_deg * kDegree) continue;
      add_landmark(candidate.point, first_stored, candidate.keypoint1, second_stored, candidate.keypoint2);
    }
    bundle_adjust();
    frames.push_back({first_stored.frame.time, first_stored.id, SE3()});
    frames.push_back({second_stored.frame.time, second_stored.id, SE3()});
    initialized = true;
    last_pose = second_stored.frame.T_world_camera;
    last_pose_time = second_stored.frame.time;
    const double elapsed = second_stored.frame.time - first_stored.frame.time;
    velocity = elapsed > 0.0 ? SE3::Tangent((first_stored.frame.T_world_camera.inverse() * last_pose).log() / elapsed) : SE3::Tangent::Zero();
    last_keyframe_tracked = static_cast<int>(landmarks.size());
    frames_since_keyframe = 0;
    logger()->info("visual odometry: initialized with {} landmarks", landmarks.size());
    result.state = TrackingState::kTracking;
    result.T_world_camera = last_pose;
    result.tracked_landmarks = static_cast<int>(landmarks.size());
    result.keyframe = true;
    result.reason.clear();
    result.map_origin_time = first_stored.frame.time;
    return result;
  }

  // Descriptor matching of a frame against a reference or a map: ratio 0.9, mutual.
  DescriptorMatcherConfig descriptor_matcher() const {
    DescriptorMatcherConfig matcher;
    matcher.ratio = 0.9;
    matcher.float_ratio = 0.9;
    matcher.max_distance = config.max_descriptor_distance;
    matcher.max_float_distance = config.max_float_descriptor_distance;
    return matcher;
  }

  // ---- tracking ----

  // Landmark -> keypoint matches by projection at T_camera_world (projection_matching.hpp),
  // the search radius scaled by radius_scale.
  std::vector<std::pair<int, int>> match_by_projection(const Frame& frame, const SE3& T_camera_world, const std::vector<int>& landmark_ids,
                                                       double radius_scale) const {
    std::vector<ProjectedLandmark> queries;
    queries.reserve(landmark_ids.size());
    for (int landmark_id : landmark_ids) {
      const Landmark& landmark = landmarks.at(landmark_id);
      queries.push_back({landmark.position, landmark.descriptor, landmark.octave, landmark_id});
    }
    ProjectionSearch search;
    search.radius_px = config.projection_search_radius_px * radius_scale;
    search.scale_factor = config.features.scale_factor;
    search.max_descriptor_distance = max_distance(frame.features.descriptors);
    return vision::match_by_projection(queries, frame.features, KeypointGrid(frame.features.keypoints, image_size, 32), camera, T_camera_world, search);
  }

  PoseRefinement refine(const Frame& frame, const SE3& T_camera_world, const std::vector<std::pair<int, int>>& matches) const {
    std::vector<PoseObservation> observations;
    observations.reserve(matches.size());
    for (const auto& [keypoint, landmark_id] : matches) {
      observations.push_back({landmarks.at(landmark_id).position, pixel_of(frame, static_cast<std::size_t>(keypoint)),
                              sigma(frame.features.keypoints[static_cast<std::size_t>(keypoint)].octave)});
    }
    return refine_pose(T_camera_world, observations, camera);
  }

  // The landmarks the given keyframes see, each once, with the descriptor of that observation.
  std::vector<int> landmarks_seen_by(const std::vector<int>& keyframe_ids, cv::Mat* descriptors = nullptr) const {
    std::vector<int> ids;
    std::set<int> seen;
    for (int keyframe_id : keyframe_ids) {
      const Frame& keyframe = keyframes.at(keyframe_id).frame;
      for (std::size_t k = 0; k < keyframe.landmark.size(); ++k) {
        const int id = keyframe.landmark[k];
        if (id < 0 || !landmarks.count(id) || !seen.insert(id).second) continue;
        ids.push_back(id);
        if (descriptors != nullptr) descriptors->push_back(keyframe.features.descriptors.row(static_cast<int>(k)));
      }
    }
    return ids;
  }

  // T_camera_world of a frame from descriptor matches against the given keyframes' landmarks
  // (PnP RANSAC on undistorted bearings), with at least min_inliers inliers.
  std::optional<SE3> solve_pnp(const Frame& frame, const std::vector<int>& keyframe_ids, int min_inliers, double min_inlier_share = 0.0) const {
    cv::Mat descriptors;
    const std::vector<int> candidate_landmarks = landmarks_seen_by(keyframe_ids, &descriptors);
    if (static_cast<int>(candidate_landmarks.size()) < min_inliers) return std::nullopt;
    std::vector<cv::Point3d> object_points;
    std::vector<cv::Point2d> image_points;
    for (const FeatureMatch& match : match_descriptors(descriptors, frame.features.descriptors, descriptor_matcher())) {
      const auto k = static_cast<std::size_t>(match.train);
      if (!has_normalized(frame, k)) continue;
      const Eigen::Vector3d& p = landmarks.at(candidate_landmarks[static_cast<std::size_t>(match.query)]).position;
      object_points.emplace_back(p.x(), p.y(), p.z());
      image_points.emplace_back(frame.normalized[k].x(), frame.normalized[k].y());
    }
    if (static_cast<int>(object_points.size()) < min_inliers) return std::nullopt;
    const std::optional<PnpSolution> solved = solve_pnp_ransac(object_points, image_points, 2.0 * config.pixel_sigma / camera.fx, 300);
    const std::size_t inliers = solved ? solved->inliers.size() : 0;
    if (static_cast<int>(inliers) < min_inliers || static_cast<double>(inliers) < min_inlier_share * static_cast<double>(object_points.size())) {
      logger()->debug("visual odometry: PnP: {} matches, {} inliers: refused", object_points.size(), inliers);
      return std::nullopt;
    }
    return solved->T_camera_world;
  }

  // Pose of a frame the motion model cannot place, against the last three keyframes.
  std::optional<SE3> relocalize(const Frame& frame) const {
    std::vector<int> recent;
    for (auto it = keyframes.rbegin(); it != keyframes.rend() && recent.size() < 3; ++it) recent.push_back(it->first);
    return solve_pnp(frame, recent, config.min_tracked_landmarks);
  }

  VisualOdometryFrame track(Frame frame) {
    VisualOdometryFrame result;
    result.time = frame.time;
    const SE3 predicted = last_pose * SE3::exp(velocity * (frame.time - last_pose_time));
    const std::vector<int> local = local_landmarks();
    SE3 T_camera_world = predicted.inverse();
    std::vector<std::pair<int, int>> matches = match_by_projection(frame, T_camera_world, local, 1.0);
    if (static_cast<int>(matches.size()) < 2 * config.min_tracked_landmarks) matches = match_by_projection(frame, T_camera_world, local, 3.0);
    PoseRefinement refined = refine(frame, T_camera_world, matches);
    logger()->debug("visual odometry: frame {:.3f}: {} local landmarks, {} matched, {} inliers", frame.time, local.size(), matches.size(), refined.inliers);
    if (refined.inliers < config.min_tracked_landmarks) {
      if (std::optional<SE3> relocalized = relocalize(frame)) {
        matches = match_by_projection(frame, *relocalized, local, 1.0);
        refined = refine(frame, *relocalized, matches);
        result.relocalized = refined.inliers >= config.min_tracked_landmarks;
      }
    }
    if (refined.inliers < config.min_tracked_landmarks) {
      result.state = TrackingState::kLost;
      result.reason = fmt::format("{} landmarks tracked (< {})", refined.inliers, config.min_tracked_landmarks);
      lost = true;
      ++counts.lost_frames;
      // Stereo: the frame's own stereo points start the map again at the predicted pose (the
      // trajectory goes on, its error since the last tracked frame kept).
      if (right_camera) {
        frame.T_world_camera = predicted;
        if (restart_from_stereo(std::move(frame))) result.reason += ": map restarted from this stereo frame at the predicted pose";
      }
      velocity.setZero();
      return result;
    }
    if (lost && result.relocalized) ++counts.relocalizations;
    lost = false;
    for (std::size_t i = 0; i < matches.size(); ++i) {
      if (refined.inlier[i]) frame.landmark[static_cast<std::size_t>(matches[i].first)] = matches[i].second;
    }
    frame.T_world_camera = refined.T_camera_world.inverse();
    // The anchor's pose as the bundle adjustment has left it (it may have become a keyframe).
    const auto anchor_pose = [this] { return keyframes.at(still_anchor_record.keyframe).frame.T_world_camera * still_anchor_record.T_keyframe_camera; };
    const bool standing = still_anchor && standing_still(frame, *still_anchor) &&
                          (!right_camera || (frame.T_world_camera.translation() - anchor_pose().translation()).norm() <= config.standstill_max_translation);
    if (standing) {
      frame.T_world_camera = anchor_pose();
      result.moving_landmarks_removed = remove_moving_landmarks(frame, matches);
    }
    const double elapsed = frame.time - last_pose_time;
    if (elapsed > 0.0) velocity = (last_pose.inverse() * frame.T_world_camera).log() / elapsed;
    last_pose = frame.T_world_camera;
    last_pose_time = frame.time;
    ++frames_since_keyframe;
    const int reference_keyframe = keyframes.rbegin()->first;
    frames.push_back({frame.time, reference_keyframe, keyframes.rbegin()->second.frame.T_world_camera.inverse() * frame.T_world_camera});
    ++counts.tracked_frames;

    result.state = TrackingState::kTracking;
    result.T_world_camera = frame.T_world_camera;
    result.tracked_landmarks = refined.inliers;
    result.standing_still = standing;
    if (standing) ++counts.standstill_frames;
    if (standing) return result;
    still_anchor = anchor_of(frame);
    if (refined.inliers < config.keyframe_tracked_ratio * last_keyframe_tracked || frames_since_keyframe >= config.max_frames_between_keyframes) {
      result.keyframe = true;
      // Mapped inline: the keyframe's adjusted pose (and a loop it closed) are known now.
      if (add_keyframe(std::move(frame))) {
        result.T_world_camera = last_pose;
        result.loop_closed = std::exchange(loop_closed_by_mapping, false);
      }
    }
    still_anchor_record = frames.back();
    return result;
  }

  // Standstill: a large share of the anchor's keypoints (the last frame tracked in motion) are
  // found again at the same pixel (within standstill_pixels, same octave, a close descriptor).
  // This does not depend on the pose estimate: moving objects in view (a passing truck) cannot
  // fake it or hide it. The pose is then held at the anchor's and no keyframe is added: without
  // a baseline, anything that moves would be triangulated from pose noise and drag the
  // estimate. The anchor stays while standing, so a slow creep adds up until it shows.
  bool standing_still(const Frame& frame, const Frame& anchor) const {
    const KeypointGrid grid(frame.features.keypoints, image_size, 16);
    const double radius = config.standstill_pixels;
    const int close = max_distance(anchor.features.descriptors) / 2;
    int still = 0;
    // Still keypoints per cell of a 4 x 4 grid over the image: moving toward distant features
    // keeps those around the point it moves toward at their pixels, a standstill keeps them
    // everywhere, so most cells with keypoints must have a still share of their own.
    constexpr int kCells = 4;
    std::array<int, kCells * kCells> cell_keypoints{}, cell_still{};
    const auto cell_of = [this](const cv::Point2f& point) {
      const int column = std::clamp(static_cast<int>(point.x * kCells / image_size.width), 0, kCells - 1);
      const int row = std::clamp(static_cast<int>(point.y * kCells / image_size.height), 0, kCells - 1);
      return static_cast<std::size_t>(row * kCells + column);
    };
    for (std::size_t k = 0; k < anchor.features.size(); ++k) {
      const cv::KeyPoint& keypoint = anchor.features.keypoints[k];
      bool found = false;
      grid.for_each_near(keypoint.pt.x, keypoint.pt.y, radius, [&](int candidate) {
        const cv::KeyPoint& other = frame.features.keypoints[static_cast<std::size_t>(candidate)];
        found = found || (other.octave == keypoint.octave && cv::norm(other.pt - keypoint.pt) <= radius &&
                          descriptor_distance(anchor.features.descriptors, static_cast<int>(k), frame.features.descriptors, candidate) <= close);
      });
      still += found;
      ++cell_keypoints[cell_of(keypoint.pt)];
      cell_still[cell_of(keypoint.pt)] += found;
    }
    const double share = static_cast<double>(still) / static_cast<double>(std::max<std::size_t>(1, anchor.features.size()));
    int occupied = 0, still_cells = 0;
    for (std::size_t cell = 0; cell < cell_keypoints.size(); ++cell) {
      if (cell_keypoints[cell] < 4) continue;
      ++occupied;
      still_cells += cell_still[cell] >= config.standstill_share * cell_keypoints[cell];
    }
    return share >= config.standstill_share && 2 * still_cells >= occupied;
  }

  // While the camera stands still the world does not move in the image: a landmark whose
  // keypoint has moved more than moving_object_pixels (times its octave scale) from where the
  // anchor frame saw it sits on something that moves (a passing vehicle) and is removed from the
  // map, so it cannot drag the pose once the camera moves again. Image displacements, not
  // reprojection errors: a standstill may hide a creep of a few centimetres, which moves near
  // points by a few pixels. Returns how many were removed.
  int remove_moving_landmarks(const Frame& frame, const std::vector<std::pair<int, int>>& matches) {
    std::map<int, std::size_t> in_anchor;
    for (std::size_t k = 0; k < still_anchor->landmark.size(); ++k) {
      if (still_anchor->landmark[k] >= 0) in_anchor.emplace(still_anchor->landmark[k], k);
    }
    int removed = 0;
    for (const auto& [keypoint, landmark_id] : matches) {
      const auto seen = in_anchor.find(landmark_id);
      if (seen == in_anchor.end() || !landmarks.count(landmark_id)) continue;
      const double displacement = (pixel_of(frame, static_cast<std::size_t>(keypoint)) - pixel_of(*still_anchor, seen->second)).norm();
      if (displacement > config.moving_object_pixels * sigma(frame.features.keypoints[static_cast<std::size_t>(keypoint)].octave) / config.pixel_sigma) {
        remove_landmark(landmark_id);
        ++removed;
      }
    }
    counts.moving_landmarks_removed += removed;
    return removed;
  }

  // ---- keyframes ----

  // A tracked frame becomes a keyframe: it observes the landmarks it tracked, and its local
  // mapping starts (on its own thread with local_mapping_thread, else here). Returns whether
  // the mapping is done (inline).
  bool add_keyframe(Frame frame) {
    const int id = next_keyframe_id++;
    Keyframe& keyframe = keyframes.emplace(id, Keyframe{id, std::move(frame)}).first->second;
    for (std::size_t k = 0; k < keyframe.frame.landmark.size(); ++k) {
      const int landmark_id = keyframe.frame.landmark[k];
      if (landmark_id < 0) continue;
      Landmark& landmark = landmarks.at(landmark_id);
      landmark.observations.emplace_back(id, static_cast<int>(k));
      landmark.descriptor = keyframe.frame.features.descriptors.row(static_cast<int>(k)).clone();
      landmark.octave = keyframe.frame.features.keypoints[k].octave;
    }
    frames.back() = {keyframe.frame.time, id, SE3()};
    frames_since_keyframe = 0;
    if (!config.local_mapping_thread) {
      map_keyframe(id);
      return true;
    }
    // The caller may reuse its image buffers once track() returns.
    keyframe.frame.right_image = keyframe.frame.right_image.clone();
    mapping = std::async(std::launch::async, [this, id] { map_keyframe(id); });
    return false;
  }

  // Local mapping of keyframe `id`: stereo points, triangulation against the previous
  // keyframes, culling, the window's bundle adjustment, loop closure; then the motion model
  // continues from the keyframe's adjusted pose.
  void map_keyframe(int id) {
    const auto start = std::chrono::steady_clock::now();
    Keyframe& keyframe = keyframes.at(id);
    const int tracked = static_cast<int>(std::count_if(keyframe.frame.landmark.begin(), keyframe.frame.landmark.end(), [](int l) { return l >= 0; }));
    int older = 0, created = 0;
    if (right_camera) {
      match_stereo(keyframe.frame);
      created += add_stereo_landmarks(keyframe);
    }
    for (auto it = std::next(keyframes.rbegin()); it != keyframes.rend() && older < config.triangulation_keyframes; ++it, ++older) {
      created += triangulate_new(it->second, keyframe);
    }
    logger()->debug("visual odometry: keyframe {} tracks {} landmarks, {} new", id, tracked, created);
    cull_unconfirmed_landmarks(id);
    bundle_adjust();
    const auto loop_start = std::chrono::steady_clock::now();
    loop_closed_by_mapping = close_loop(id) || loop_closed_by_mapping;
    counts.loop_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - loop_start).count();
    // The frame's pose after the adjustment (and the loop correction).
    last_pose = keyframe.frame.T_world_camera;
    // What the next frames are compared with: the landmarks this keyframe sees that other
    // keyframes confirm (a stereo keyframe's new points, seen by it alone, would make every
    // following frame look short of landmarks).
    last_keyframe_tracked = static_cast<int>(std::count_if(keyframe.frame.landmark.begin(), keyframe.frame.landmark.end(),
                                                           [&](int l) { return l >= 0 && landmarks.at(l).observations.size() >= 2; }));
    ++counts.keyframes;
    counts.mapping_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }

  // A landmark that three keyframes after its creation is still seen by fewer than three was a
  // chance match or lies on something that moved (ORB-SLAM's recent map point culling).
  void cull_unconfirmed_landmarks(int newest_keyframe) {
    std::vector<int> unconfirmed;
    for (const auto& [landmark_id, landmark] : landmarks) {
      if (newest_keyframe - landmark.created_at == 3 && observation_count(landmark) < 3) unconfirmed.push_back(landmark_id);
    }
    for (int landmark_id : unconfirmed) remove_landmark(landmark_id);
  }

  // New landmarks: each keypoint of the newer keyframe without a landmark is matched along its
  // epipolar line in the older keyframe (within 2 sigma of its octave) to the keypoint nearest
  // in descriptor (ratio 0.9 against the runner-up on the line), then triangulated and checked.
  int triangulate_new(const Keyframe& older, Keyframe& newer) {
    const SE3 T_camera1_world = older.frame.T_world_camera.inverse(), T_camera2_world = newer.frame.T_world_camera.inverse();
    const SE3 T_camera1_camera2 = T_camera1_world * newer.frame.T_world_camera;
    if (T_camera1_camera2.translation().norm() < 1e-9) return 0;
    if (right_camera && T_camera1_camera2.translation().norm() < config.min_triangulation_baseline_share * T_left_right.translation().norm()) return 0;
    // Essential matrix E = [t]x R of camera 1 from camera 2: x1^T E x2 = 0 (normalized).
    const Eigen::Matrix3d essential = SO3::hat(T_camera1_camera2.translation()) * T_camera1_camera2.rotation().matrix();
    // The older keyframe's free keypoints by octave (ascending within each), their normalized
    // coordinates beside them: the search reads only the octaves within one of the keypoint's.
    const int octaves = static_cast<int>(octave_scale.size());
    std::vector<std::vector<int>> free1(static_cast<std::size_t>(octaves));
    std::vector<std::vector<Eigen::Vector2d>> free1_normalized(static_cast<std::size_t>(octaves));
    for (std::size_t k = 0; k < older.frame.landmark.size(); ++k) {
      if (older.frame.landmark[k] >= 0 || !has_normalized(older.frame, k)) continue;
      const auto octave = static_cast<std::size_t>(older.frame.features.keypoints[k].octave);
      free1[octave].push_back(static_cast<int>(k));
      free1_normalized[octave].push_back(older.frame.normalized[k]);
    }
    std::vector<std::pair<int, int>> owner(older.frame.landmark.size(), {-1, std::numeric_limits<int>::max()});  // (k2, distance)
    for (std::size_t k2 = 0; k2 < newer.frame.landmark.size(); ++k2) {
      if (newer.frame.landmark[k2] >= 0 || !has_normalized(newer.frame, k2)) continue;
      const Eigen::Vector3d line = essential * newer.frame.normalized[k2].homogeneous();
      const double line_norm = line.head<2>().norm();
      if (line_norm < 1e-12) continue;
      const int octave2 = newer.frame.features.keypoints[k2].octave;
      // Equal distances fail the ratio test, so the order of the offers does not matter.
      NearestCandidates nearest;
      for (int octave1 = std::max(0, octave2 - 1); octave1 <= std::min(octaves - 1, octave2 + 1); ++octave1) {
        const std::vector<int>& keypoints1 = free1[static_cast<std::size_t>(octave1)];
        const std::vector<Eigen::Vector2d>& normalized1 = free1_normalized[static_cast<std::size_t>(octave1)];
        const double max_epipolar_px = 2.0 * sigma(octave1);
        for (std::size_t i = 0; i < keypoints1.size(); ++i) {
          const double epipolar_px = std::abs(normalized1[i].homogeneous().dot(line)) / line_norm * camera.fx;
          if (epipolar_px > max_epipolar_px) continue;
          nearest.offer(keypoints1[i], descriptor_distance(older.frame.features.descriptors, keypoints1[i], newer.frame.features.descriptors, static_cast<int>(k2)));
        }
      }
      if (!nearest.passes(0.9, max_distance(newer.frame.features.descriptors))) continue;
      const int best_k1 = nearest.index, best = nearest.best;
      auto& slot = owner[static_cast<std::size_t>(best_k1)];
      if (best < slot.second) slot = {static_cast<int>(k2), best};
    }
    int created = 0;
    for (std::size_t k1 = 0; k1 < owner.size(); ++k1) {
      if (owner[k1].first < 0) continue;
      const auto k2 = static_cast<std::size_t>(owner[k1].first);
      const std::optional<Eigen::Vector3d> point = triangulate(T_camera1_world, older.frame.normalized[k1], T_camera2_world, newer.frame.normalized[k2]);
      if (!point) continue;
      if (triangulation_angle(T_camera1_world, T_camera2_world, *point) < config.min_triangulation_angle_deg * kDegree) continue;
      const PoseObservation in1{*point, pixel_of(older.frame, k1), sigma(older.frame.features.keypoints[k1].octave)};
      const PoseObservation in2{*point, pixel_of(newer.frame, k2), sigma(newer.frame.features.keypoints[k2].octave)};
      if (reprojection_chi2(T_camera1_world, in1, camera) > kChi2Pixel95 || reprojection_chi2(T_camera2_world, in2, camera) > kChi2Pixel95) continue;
      add_landmark(*point, older, static_cast<int>(k1), newer, static_cast<int>(k2));
      ++created;
    }
    return created;
  }

  // ---- loop closure ----

  // Loop verification: the PnP inliers' least share of the descriptor matches, and the most the
  // refinement may move the PnP pose (times the landmarks' median depth; radians).
  static constexpr double kLoopMinInlierShare = 0.2;
  static constexpr double kLoopMaxRefinement = 0.05;

  // Adds the keyframes not in the place database yet, then looks for a loop closing at the
  // newest keyframe `keyframe_id` and corrects the map when one is verified.
  // Place recognition over the keyframes: bags of words (ORB) or VLAD vectors (learned).
  bool place_recognition() const { return places.has_value() || place_model != nullptr; }

  void add_place(const Frame& keyframe) {
    if (place_model) {
      // describe() fails only on descriptors of another kind, which create() rules out.
      Result<Eigen::VectorXf> described = place_model->describe(keyframe.features.descriptors);
      place_vectors.push_back(described ? std::move(described).value() : Eigen::VectorXf::Zero(place_model->dimensions()));
    } else {
      places->add(vocabulary->transform(keyframe.features.descriptors));
    }
  }

  double place_score(int entry_a, int entry_b) const {
    if (place_model) return VladModel::similarity(place_vectors[static_cast<std::size_t>(entry_a)], place_vectors[static_cast<std::size_t>(entry_b)]);
    return Vocabulary::score(places->bow(entry_a), places->bow(entry_b));
  }

  // The `count` best entries among [0, before) scoring at least min_score, best first.
  std::vector<PlaceMatch> query_places(int entry, int count, int before, double min_score) const {
    if (!place_model) return places->query(places->bow(entry), count, before, min_score);
    return rank_places(place_vectors, place_vectors[static_cast<std::size_t>(entry)], count, before, min_score);
  }

  bool close_loop(int keyframe_id) {
    if (!place_recognition()) return false;
    for (auto it = keyframes.upper_bound(place_keyframe.empty() ? -1 : place_keyframe.back()); it != keyframes.end(); ++it) {
      add_place(it->second.frame);
      place_keyframe.push_back(it->first);
    }
    const int entry = static_cast<int>(place_keyframe.size()) - 1;
    if (place_keyframe.back() != keyframe_id || ++keyframes_since_loop <= config.loop_cooldown_keyframes) return false;
    const int before = entry - config.loop_min_keyframe_gap + 1;
    if (before <= 0) return false;
    double min_score = 1.0;
    for (int previous = std::max(0, entry - 3); previous < entry; ++previous) min_score = std::min(min_score, place_score(entry, previous));
    for (const PlaceMatch& candidate : query_places(entry, 3, before, std::max(min_score, 0.01))) {
      ++counts.loop_candidates;
      const int candidate_id = place_keyframe[static_cast<std::size_t>(candidate.entry)];
      const std::optional<std::pair<Similarity, int>> loop = verify_loop(candidate_id, keyframe_id);
      if (!loop) continue;
      correct_loop(candidate_id, keyframe_id, loop->first);
      logger()->info("visual odometry: loop closed: keyframe {} ({:.2f} s) with keyframe {} ({:.2f} s), score {:.3f}, {} inliers, scale {:.3f}",
                     keyframe_id, keyframes.at(keyframe_id).frame.time, candidate_id, keyframes.at(candidate_id).frame.time, candidate.score,
                     loop->second, loop->first.scale);
      keyframes_since_loop = 0;
      ++counts.loop_closures;
      return true;
    }
    return false;
  }

  // The similarity taking the newest keyframe's map onto the candidate's: the keyframe is
  // placed in the candidate's map by PnP RANSAC against the landmarks of the candidate and its
  // two neighbours on each side, refined on their projections; monocular, the scale is the
  // median ratio of the depths of the matched landmarks in the two maps. None when fewer than
  // loop_min_inliers landmarks agree.
  std::optional<std::pair<Similarity, int>> verify_loop(int candidate_id, int current_id) const {
    std::vector<int> neighbours;
    for (auto it = keyframes.find(candidate_id), first = it; it != keyframes.end() && std::distance(first, it) <= 2; ++it) neighbours.push_back(it->first);
    for (auto it = std::make_reverse_iterator(keyframes.find(candidate_id)); it != keyframes.rend() && neighbours.size() < 5; ++it) neighbours.push_back(it->first);
    const Frame& current = keyframes.at(current_id).frame;
    const std::optional<SE3> placed = solve_pnp(current, neighbours, config.loop_min_inliers, kLoopMinInlierShare);
    if (!placed) {
      logger()->debug("visual odometry: loop candidate keyframe {} for {}: no PnP solution", candidate_id, current_id);
      return std::nullopt;
    }
    const std::vector<std::pair<int, int>> matches = match_by_projection(current, *placed, landmarks_seen_by(neighbours), 1.0);
    const PoseRefinement refined = refine(current, *placed, matches);
    logger()->debug("visual odometry: loop candidate keyframe {} for {}: {} of {} projected matches agree", candidate_id, current_id, refined.inliers, matches.size());
    if (refined.inliers < config.loop_min_inliers) return std::nullopt;
    // A true placement barely moves when refined on many more landmarks; one that slides
    // (a periodic texture such as a tiled floor offers a shifted fit) is refused.
    std::vector<double> depths;
    for (std::size_t i = 0; i < matches.size(); ++i) {
      if (refined.inlier[i]) depths.push_back(refined.T_camera_world.act(landmarks.at(matches[i].second).position).z());
    }
    std::nth_element(depths.begin(), depths.begin() + static_cast<std::ptrdiff_t>(depths.size() / 2), depths.end());
    const SE3 refinement = *placed * refined.T_camera_world.inverse();
    if (refinement.translation().norm() > kLoopMaxRefinement * depths[depths.size() / 2] || refinement.rotation().angle() > kLoopMaxRefinement) {
      logger()->debug("visual odometry: loop candidate keyframe {} for {}: refinement moved the PnP pose {:.3f} (median depth {:.3f}), {:.2f} deg: refused",
                      candidate_id, current_id, refinement.translation().norm(), depths[depths.size() / 2], refinement.rotation().angle() / kDegree);
      return std::nullopt;
    }
    double scale = 1.0;
    if (!right_camera) {
      const SE3 T_current_world = current.T_world_camera.inverse();
      std::vector<double> ratios;
      for (std::size_t i = 0; i < matches.size(); ++i) {
        const int own = current.landmark[static_cast<std::size_t>(matches[i].first)];
        if (!refined.inlier[i] || own < 0 || !landmarks.count(own)) continue;
        const double depth_candidate = refined.T_camera_world.act(landmarks.at(matches[i].second).position).z();
        const double depth_current = T_current_world.act(landmarks.at(own).position).z();
        if (depth_candidate > 0.0 && depth_current > 0.0) ratios.push_back(depth_candidate / depth_current);
      }
      if (ratios.size() < 10) return std::nullopt;
      std::nth_element(ratios.begin(), ratios.begin() + static_cast<std::ptrdiff_t>(ratios.size() / 2), ratios.end());
      scale = ratios[ratios.size() / 2];
    }
    // A point p of the current map: q = T_world_current^-1 p in the current camera, then
    // T_world_current_corrected (scale q) in the candidate's map.
    const Similarity S = Similarity::from(refined.T_camera_world.inverse()) * Similarity{Eigen::Quaterniond::Identity(), Eigen::Vector3d::Zero(), scale} *
                         Similarity::from(current.T_world_camera).inverse();
    return std::make_pair(S, refined.inliers);
  }

  // Pose graph over the keyframes from the candidate on (the candidate and older held), the loop
  // edge from the verified similarity S (current map -> candidate map); landmarks, frames and the
  // motion model follow their keyframes.
  void correct_loop(int candidate_id, int current_id, const Similarity& S_corrected_current) {
    std::map<int, Similarity> S_world_keyframe;
    for (auto it = keyframes.find(candidate_id); it != keyframes.end(); ++it) S_world_keyframe[it->first] = Similarity::from(it->second.frame.T_world_camera);
    const std::map<int, Similarity> before = S_world_keyframe;
    std::vector<SimilarityEdge> edges;
    std::vector<int> ids;
    for (const auto& entry : S_world_keyframe) ids.push_back(entry.first);
    for (std::size_t i = 0; i < ids.size(); ++i) {
      for (std::size_t j = i + 1; j < std::min(ids.size(), i + 3); ++j) {
        const bool across_restart = std::any_of(ids.begin() + static_cast<std::ptrdiff_t>(i) + 1, ids.begin() + static_cast<std::ptrdiff_t>(j) + 1,
                                                [&](int id) { return keyframes.at(id).starts_map; });
        edges.push_back({ids[i], ids[j], before.at(ids[i]).inverse() * before.at(ids[j]), across_restart ? 1e-3 : 1.0});
      }
    }
    // Earlier loops inside the corrected stretch keep their keyframes' relative poses.
    for (const auto& [from, to] : loops) {
      if (from >= candidate_id) edges.push_back({from, to, before.at(from).inverse() * before.at(to), 10.0});
    }
    const Similarity S_world_current_corrected = S_corrected_current * before.at(current_id);
    edges.push_back({candidate_id, current_id, before.at(candidate_id).inverse() * S_world_current_corrected, 10.0});
    loops.emplace_back(candidate_id, current_id);
    // Start from the corrected pose for the current keyframe's window (the rest follows).
    for (int id : window()) {
      if (id > candidate_id) S_world_keyframe[id] = S_corrected_current * before.at(id);
    }
    const SimilarityPoseGraphSummary summary = optimize_similarity_pose_graph(S_world_keyframe, edges, {candidate_id}, right_camera.has_value(), 20);
    logger()->debug("visual odometry: loop pose graph: {} keyframes, cost {:.4g} -> {:.4g} in {} iterations", ids.size(), summary.initial_cost,
                    summary.final_cost, summary.iterations);
    // Corrections: S_new S_old^-1 per keyframe.
    std::map<int, Similarity> correction;
    for (const auto& [id, pose] : S_world_keyframe) correction[id] = pose * before.at(id).inverse();
    for (auto& [landmark_id, landmark] : landmarks) {
      const auto found = correction.find(landmark.created_at);
      if (found != correction.end() && found->first != candidate_id) landmark.position = found->second * landmark.position;
    }
    for (const auto& [id, pose] : S_world_keyframe) keyframes.at(id).frame.T_world_camera = pose.rigid();
    for (FrameRecord& record : frames) {
      const auto found = S_world_keyframe.find(record.keyframe);
      if (found != S_world_keyframe.end()) record.T_keyframe_camera.translation() *= found->second.scale;
    }
    logger()->debug("visual odometry: loop correction moved keyframe {} from ({:.3f} {:.3f} {:.3f}) to ({:.3f} {:.3f} {:.3f}); loop said ({:.3f} {:.3f} {:.3f})", current_id,
                    before.at(current_id).translation.x(), before.at(current_id).translation.y(), before.at(current_id).translation.z(),
                    S_world_keyframe.at(current_id).translation.x(), S_world_keyframe.at(current_id).translation.y(), S_world_keyframe.at(current_id).translation.z(),
                    S_world_current_corrected.translation.x(), S_world_current_corrected.translation.y(), S_world_current_corrected.translation.z());
    const double scale = S_world_keyframe.at(current_id).scale;
    velocity.head<3>() *= scale;
    if (still_anchor) still_anchor.reset();
  }

  // Local bundle adjustment over the window (ORB-SLAM's two passes): Huber-robust iterations,
  // the observations then over the chi-square bound left out, and the same again. Monocular:
  // the window's two oldest keyframes are held (gauge and scale); stereo: the oldest. A result
  // that moves a keyframe farther than the window's own length is refused (a weakly tied
  // keyframe sliding off): the map keeps its values.
  void bundle_adjust() {
    const std::vector<int> window_ids = window();
    const std::set<int> in_window(window_ids.begin(), window_ids.end());
    BundleProblem problem;
    problem.cameras.push_back({camera, SE3()});
    if (right_camera) problem.cameras.push_back({*right_camera, T_left_right});
    std::map<int, int> pose_index;
    double window_length = 0.0;
    for (std::size_t i = 0; i < window_ids.size(); ++i) {
      const SE3& pose = keyframes.at(window_ids[i]).frame.T_world_camera;
      pose_index[window_ids[i]] = static_cast<int>(i);
      problem.T_world_body.push_back(pose);
      if (i > 0) window_length += (pose.translation() - keyframes.at(window_ids[i - 1]).frame.T_world_camera.translation()).norm();
      problem.pose_fixed.push_back(i < (right_camera ? 1u : 2u));
    }
    std::vector<int> adjusted;
    std::vector<BundleObservation> observations;
    for (int landmark_id : local_landmarks()) {
      const Landmark& landmark = landmarks.at(landmark_id);
      if (observation_count(landmark, &in_window) < 2) continue;
      // Every observation must be in front of its camera, or the problem cannot be evaluated.
      const bool in_front = std::all_of(landmark.observations.begin(), landmark.observations.end(), [&](const auto& observation) {
        return !in_window.count(observation.first) || (keyframes.at(observation.first).frame.T_world_camera.inverse().act(landmark.position).z() > camera.min_depth);
      });
      if (!in_front) continue;
      const int point = static_cast<int>(adjusted.size());
      problem.points_world.push_back(landmark.position);
      adjusted.push_back(landmark_id);
      for (const auto& [keyframe_id, keypoint] : landmark.observations) {
        if (!in_window.count(keyframe_id)) continue;
        const Frame& frame = keyframes.at(keyframe_id).frame;
        const auto k = static_cast<std::size_t>(keypoint);
        const int pose = pose_index.at(keyframe_id);
        observations.push_back({pose, point, 0, pixel_of(frame, k), sigma(frame.features.keypoints[k].octave)});
        if (has_right(frame, k)) {
          observations.push_back({pose, point, 1, right_pixel_of(frame, k), sigma(frame.right_features.keypoints[static_cast<std::size_t>(frame.right_keypoint[k])].octave)});
        }
      }
    }
    if (observations.empty() || config.bundle_adjustment_iterations == 0) return;
    BundleAdjustmentConfig adjustment;
    adjustment.max_iterations = config.bundle_adjustment_iterations;
    adjustment.huber_threshold = std::sqrt(kChi2Pixel95);
    std::vector<bool> used(observations.size(), true);
    for (int pass = 0; pass < 2; ++pass) {
      problem.observations.clear();
      for (std::size_t i = 0; i < observations.size(); ++i) {
        if (used[i]) problem.observations.push_back(observations[i]);
      }
      // A failed adjustment leaves the problem's values as they were.
      Result<BundleAdjustmentSummary> optimized = vision::bundle_adjust(problem, adjustment);
      if (!optimized) {
        logger()->warn("visual odometry: local bundle adjustment failed: {}", optimized.error().message);
        break;
      }
      for (std::size_t i = 0; i < observations.size(); ++i) {
        const BundleObservation& observation = observations[i];
        Eigen::Vector2d residual;
        used[i] = used[i] && bundle_residual(problem.T_world_body[static_cast<std::size_t>(observation.pose)], problem.points_world[static_cast<std::size_t>(observation.point)],
                                             problem.cameras[static_cast<std::size_t>(observation.camera)], observation, residual, nullptr, nullptr) &&
                  residual.squaredNorm() <= kChi2Pixel95;
      }
    }
    const double limit = std::max(window_length, 1e-6);
    for (int keyframe_id : window_ids) {
      const double moved = (problem.T_world_body[static_cast<std::size_t>(pose_index.at(keyframe_id))].translation() -
                            keyframes.at(keyframe_id).frame.T_world_camera.translation()).norm();
      if (moved > limit) {
        logger()->warn("visual odometry: bundle adjustment moved keyframe {} by {:.3f} (window length {:.3f}): refused", keyframe_id, moved, window_length);
        return;
      }
    }
    for (int keyframe_id : window_ids) keyframes.at(keyframe_id).frame.T_world_camera = problem.T_world_body[static_cast<std::size_t>(pose_index.at(keyframe_id))];
    for (std::size_t point = 0; point < adjusted.size(); ++point) landmarks.at(adjusted[point]).position = problem.points_world[point];
    // Observations that remain outliers are removed; landmarks left with one are culled.
    for (int landmark_id : local_landmarks()) {
      std::vector<int> outliers;
      for (const auto& [keyframe_id, keypoint] : landmarks.at(landmark_id).observations) {
        if (!in_window.count(keyframe_id)) continue;
        const Frame& frame = keyframes.at(keyframe_id).frame;
        const PoseObservation observation{landmarks.at(landmark_id).position, pixel_of(frame, static_cast<std::size_t>(keypoint)),
                                          sigma(frame.features.keypoints[static_cast<std::size_t>(keypoint)].octave)};
        if (reprojection_chi2(frame.T_world_camera.inverse(), observation, camera) > kChi2Pixel95) {
          outliers.push_back(keyframe_id);
        } else if (has_right(frame, static_cast<std::size_t>(keypoint))) {
          const PoseObservation right{observation.point_world, right_pixel_of(frame, static_cast<std::size_t>(keypoint)),
                                      sigma(frame.right_features.keypoints[static_cast<std::size_t>(frame.right_keypoint[static_cast<std::size_t>(keypoint)])].octave)};
          if (reprojection_chi2((frame.T_world_camera * T_left_right).inverse(), right, *right_camera) > kChi2Pixel95) {
            keyframes.at(keyframe_id).frame.right_keypoint[static_cast<std::size_t>(keypoint)] = -1;
          }
        }
      }
      for (int keyframe_id : outliers) remove_observation(landmark_id, keyframe_id);
      if (observation_count(landmarks.at(landmark_id)) < 2) remove_landmark(landmark_id);
    }
  }
};

VisualOdometry::VisualOdometry(std::unique_ptr<State> state) : state_(std::move(state)) {}
VisualOdometry::~VisualOdometry() = default;

Result<std::unique_ptr<VisualOdometry>> VisualOdometry::create(const PinholeCamera& camera, cv::Size image_size, const VisualOdometryConfig& config) {
  if (Status valid = validate(config); !valid) return valid.error();
  if (!(camera.fx > 0.0 && camera.fy > 0.0 && std::isfinite(camera.cx) && std::isfinite(camera.cy))) {
    return Error(fmt::format("camera: focal lengths must be positive (fx {}, fy {})", camera.fx, camera.fy), "camera");
  }
  if (image_size.width < 64 || image_size.height < 64) {
    return Error(fmt::format("image size {} x {} is smaller than 64 x 64", image_size.width, image_size.height), "image_size");
  }
  auto state = std::make_unique<State>();
  state->camera = camera;
  state->image_size = image_size;
  state->config = config;
  state->extractor = config.extractor ? config.extractor : std::make_shared<const OrbFeatureExtractor>(config.features);
  // The octaves' scales are ORB's pyramid's (an ORB extractor given brings its own); learned
  // keypoints are all of octave 0.
  if (const auto* orb = dynamic_cast<const OrbFeatureExtractor*>(state->extractor.get())) state->config.features = orb->config();
  for (int level = 0; level < state->config.features.pyramid_levels; ++level) {
    state->octave_scale.push_back(std::pow(state->config.features.scale_factor, level));
  }
  const bool binary_descriptors = state->extractor->descriptor_type() == CV_8UC1;
  if (config.place_model && (binary_descriptors || config.place_model->extractor_name() != state->extractor->name())) {
    return Error(fmt::format("VisualOdometryConfig.place_model: trained on {} descriptors, the features are {}'s", config.place_model->extractor_name(),
                             state->extractor->name()),
                 "place_model");
  }
  if (config.loop_closure && !binary_descriptors && !config.place_model) {
    logger()->warn("visual odometry: loop closure off: the bag-of-words vocabulary is of binary descriptors, {} gives float ones "
                   "(learned place recognition needs a place model for them)",
                   state->extractor->name());
  }
  if (config.loop_closure && config.place_model) state->place_model = config.place_model;
  if (config.loop_closure && binary_descriptors) {
    state->vocabulary = config.vocabulary ? config.vocabulary : default_vocabulary();
    if (state->vocabulary) state->places.emplace(state->vocabulary);
  }
  state->counts.loop_closure_enabled = state->place_recognition();
  state->counts.place_recognition = state->place_model ? "learned" : state->places ? "bow" : "";
  state->counts.features = state->extractor->name();
  state->counts.learned_matcher = config.putative_filter != nullptr;
  return std::unique_ptr<VisualOdometry>(new VisualOdometry(std::move(state)));
}

Result<std::unique_ptr<VisualOdometry>> VisualOdometry::create_stereo(const PinholeCamera& left, const PinholeCamera& right, const SE3& T_left_right,
                                                                      cv::Size image_size, const VisualOdometryConfig& config) {
  if (!(right.fx > 0.0 && right.fy > 0.0 && std::isfinite(right.cx) && std::isfinite(right.cy))) {
    return Error(fmt::format("right camera: focal lengths must be positive (fx {}, fy {})", right.fx, right.fy), "right_camera");
  }
  if (!(T_left_right.translation().norm() > 1e-3) || !T_left_right.translation().allFinite()) {
    return Error(fmt::format("stereo baseline {} m: the cameras must be at least 1 mm apart", T_left_right.translation().norm()), "T_left_right");
  }
  Result<std::unique_ptr<VisualOdometry>> odometry = create(left, image_size, config);
  if (!odometry) return odometry.error();
  (*odometry)->state_->right_camera = right;
  (*odometry)->state_->T_left_right = T_left_right;
  (*odometry)->state_->counts.scale_free = false;
  return odometry;
}

Result<std::unique_ptr<VisualOdometry>> VisualOdometry::create_rgbd(const PinholeCamera& camera, cv::Size image_size, const VisualOdometryConfig& config,
                                                                    double max_depth) {
  if (!(max_depth > 0.0) || !std::isfinite(max_depth)) return Error(fmt::format("max_depth: expected > 0 m, got {}", max_depth), "max_depth");
  Result<std::unique_ptr<VisualOdometry>> odometry =
      create_stereo(camera, camera, SE3(SO3(), Eigen::Vector3d(max_depth / config.max_stereo_depth_baselines, 0.0, 0.0)), image_size, config);
  if (odometry) (*odometry)->state_->rgbd = true;
  return odometry;
}

Result<VisualOdometryFrame> VisualOdometry::track_rgbd(double time, const cv::Mat& image, const cv::Mat& depth, const StaticMask& static_mask) {
  if (!state_->rgbd) return Error("visual odometry: track_rgbd needs an odometry made by create_rgbd", "depth");
  if (depth.size() != image.size()) {
    return Error(fmt::format("depth image is {} x {}, the colour image {} x {}", depth.cols, depth.rows, image.cols, image.rows), "depth");
  }
  if (depth.type() != CV_16UC1 && depth.type() != CV_32FC1) {
    return Error(fmt::format("depth image: type {} is neither 16-bit millimetres nor 32-bit float metres", cv::typeToString(depth.type())), "depth");
  }
  return track_frame(time, image, depth, static_mask);
}

Result<VisualOdometryFrame> VisualOdometry::track(double time, const cv::Mat& image, const StaticMask& static_mask) {
  if (state_->rgbd) return Error("RGB-D visual odometry: track_rgbd(time, image, depth) needs the depth image", "image");
  if (state_->right_camera) return Error("stereo visual odometry: track(time, left, right) needs both images", "image");
  return track_frame(time, image, cv::Mat(), static_mask);
}

Result<VisualOdometryFrame> VisualOdometry::track(double time, const cv::Mat& left, const cv::Mat& right, const StaticMask& static_mask) {
  if (!state_->right_camera) return Error("monocular visual odometry: track(time, image) takes one image", "image");
  if (state_->rgbd) return Error("RGB-D visual odometry: track_rgbd(time, image, depth) takes the depth image", "image");
  if (right.size() != left.size()) {
    return Error(fmt::format("right image is {} x {}, the left {} x {}", right.cols, right.rows, left.cols, left.rows), "right_image");
  }
  return track_frame(time, left, right, static_mask);
}

Result<VisualOdometryFrame> VisualOdometry::track_frame(double time, const cv::Mat& image, const cv::Mat& right, const StaticMask& static_mask) {
  State& s = *state_;
  if (!std::isfinite(time)) return Error("time: not finite", "time");
  if (s.last_time && time <= *s.last_time) {
    return Error(fmt::format("time {:.6f} s is not after the previous frame's {:.6f} s: frame skipped", time, *s.last_time), "time");
  }
  if (image.cols != s.image_size.width || image.rows != s.image_size.height) {
    return Error(fmt::format("image is {} x {}, the camera's calibration is for {} x {}", image.cols, image.rows, s.image_size.width, s.image_size.height), "image");
  }
  if (!static_mask.empty() && (static_mask.pixels.type() != CV_8UC1 || static_mask.pixels.size() != image.size())) {
    return Error(fmt::format("static mask: {} x {} {}, expected 8-bit single channel of the image's {} x {}", static_mask.pixels.cols, static_mask.pixels.rows,
                             cv::typeToString(static_mask.pixels.type()), image.cols, image.rows), "static_mask");
  }
  Result<ImageFeatures> features = with_context(s.extract(image, s.counts.feature_seconds, static_mask.pixels), "image");
  if (!features) return Error(features.error().message, "image");
  if (!right.empty() && !s.rgbd && (right.depth() != CV_8U || (right.channels() != 1 && right.channels() != 3 && right.channels() != 4))) {
    return Error(fmt::format("right image: type {} is not 8-bit grey, BGR or BGRA", cv::typeToString(right.type())), "right_image");
  }
  s.last_time = time;
  ++s.counts.frames;
  ++s.counts.feature_frames;
  Frame frame = s.make_frame(time, std::move(features).value());
  frame.right_image = right;
  // The features were extracted while the previous keyframe's mapping ran; the map is read from here on.
  s.finish_mapping();
  if (!s.initialized) {
    VisualOdometryFrame result = s.right_camera ? s.initialize_stereo(std::move(frame)) : s.initialize(std::move(frame));
    if (result.state == TrackingState::kTracking) s.counts.tracked_frames += s.right_camera ? 1 : 2;
    return result;
  }
  const bool loop_closed = std::exchange(s.loop_closed_by_mapping, false);
  VisualOdometryFrame result = s.track(std::move(frame));
  result.loop_closed = result.loop_closed || loop_closed;
  return result;
}

std::vector<std::pair<double, SE3>> VisualOdometry::trajectory() const {
  state_->finish_mapping();
  std::vector<std::pair<double, SE3>> poses;
  poses.reserve(state_->frames.size());
  for (const FrameRecord& record : state_->frames) poses.emplace_back(record.time, state_->keyframes.at(record.keyframe).frame.T_world_camera * record.T_keyframe_camera);
  return poses;
}

std::vector<std::pair<double, SE3>> VisualOdometry::keyframe_poses() const {
  state_->finish_mapping();
  std::vector<std::pair<double, SE3>> poses;
  for (const auto& [id, keyframe] : state_->keyframes) poses.emplace_back(keyframe.frame.time, keyframe.frame.T_world_camera);
  return poses;
}

std::vector<Eigen::Vector3d> VisualOdometry::landmark_positions() const {
  state_->finish_mapping();
  std::vector<Eigen::Vector3d> positions;
  positions.reserve(state_->landmarks.size());
  for (const auto& [id, landmark] : state_->landmarks) positions.push_back(landmark.position);
  return positions;
}

msgs::VisualLandmarkLayer VisualOdometry::landmark_layer(const std::string& camera_name) const {
  state_->finish_mapping();
  msgs::VisualLandmarkLayer layer;
  layer.camera = camera_name;
  layer.scale_free = state_->counts.scale_free;
  std::map<int, uint32_t> index_of;
  for (const auto& [id, landmark] : state_->landmarks) {
    if (landmark.observations.size() < 2 || !landmark.position.allFinite()) continue;
    index_of[id] = static_cast<uint32_t>(layer.positions.size());
    layer.positions.push_back(landmark.position.cast<float>());
    if (landmark.descriptor.type() == CV_8UC1) {
      std::array<uint8_t, 32> descriptor{};
      std::memcpy(descriptor.data(), landmark.descriptor.ptr<unsigned char>(), descriptor.size());
      layer.descriptors.push_back(descriptor);
    } else {
      layer.descriptor_type = state_->extractor->name();
      layer.float_descriptor_size = static_cast<uint32_t>(landmark.descriptor.cols);
      layer.float_descriptors.insert(layer.float_descriptors.end(), landmark.descriptor.ptr<float>(), landmark.descriptor.ptr<float>() + landmark.descriptor.cols);
    }
    layer.observations.push_back(static_cast<uint32_t>(landmark.observations.size()));
    // Depth uncertainty of a triangulated point: depth^2 sigma_px / (f baseline), with the
    // widest baseline among its observing cameras (the stereo rig's for a stereo observation).
    double baseline = 0.0, depth = std::numeric_limits<double>::infinity();
    for (const auto& [keyframe_a, keypoint_a] : landmark.observations) {
      const Frame& frame_a = state_->keyframes.at(keyframe_a).frame;
      const Eigen::Vector3d centre_a = frame_a.T_world_camera.translation();
      depth = std::min(depth, (landmark.position - centre_a).norm());
      if (has_right(frame_a, static_cast<std::size_t>(keypoint_a))) baseline = std::max(baseline, state_->T_left_right.translation().norm());
      for (const auto& [keyframe_b, keypoint_b] : landmark.observations) {
        baseline = std::max(baseline, (state_->keyframes.at(keyframe_b).frame.T_world_camera.translation() - centre_a).norm());
      }
    }
    const double sigma = baseline > 0.0 ? depth * depth * state_->config.pixel_sigma / (state_->camera.fx * baseline) : std::numeric_limits<double>::max();
    layer.position_std.push_back(static_cast<float>(std::min(sigma, 1e6)));
  }
  for (const auto& [id, keyframe] : state_->keyframes) {
    msgs::VisualKeyframe out;
    out.time = Timestamp::from_seconds(keyframe.frame.time);
    out.T_world_camera = msgs::Pose::from_se3(keyframe.frame.T_world_camera);
    for (int landmark_id : keyframe.frame.landmark) {
      const auto found = index_of.find(landmark_id);
      if (found != index_of.end()) out.landmarks.push_back(found->second);
    }
    layer.keyframes.push_back(std::move(out));
  }
  return layer;
}

VisualOdometrySummary VisualOdometry::summary() const {
  state_->finish_mapping();
  VisualOdometrySummary summary = state_->counts;
  summary.feature_seconds += state_->right_feature_seconds;
  summary.landmarks = static_cast<int>(state_->landmarks.size());
  summary.keyframes = static_cast<int>(state_->keyframes.size());
  return summary;
}

}  // namespace hanzo::fusion::vision
