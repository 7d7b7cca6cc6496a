#pragma once
// VisualOdometry: monocular or stereo visual odometry with a sparse landmark map and a sliding
// window of keyframes refined by local bundle adjustment (the tracking / local mapping split of
// ORB-SLAM, Mur-Artal et al. 2015).
//
// Threads: tracking runs in the caller's thread. A new keyframe's local mapping (stereo
// matching of its right image, triangulation, landmark culling, bundle adjustment, loop
// closure) runs either on its own thread (local_mapping_thread: track() returns the keyframe's
// tracked pose at once, the mapping runs while the caller goes on and the next frame's features
// are extracted, and the next frame is tracked once it has finished; a loop it closed is
// reported with the next frame) or inline before track() returns (the keyframe's reported pose
// is then its bundle-adjusted one). The map's work and its order are the same either way: the
// map, trajectory() and every non-keyframe result are bit-identical with and without the
// thread, and neither depends on timing (replays reproduce on any machine). Every accessor
// waits for a running mapping first.
//
//   initialization: the first frame is the reference; a later frame whose matches with it
//     give an essential matrix (RANSAC on undistorted bearings) with enough inliers, half of
//     them triangulated at an angle of at least min_initialization_parallax_deg, becomes the
//     second keyframe; its inliers are triangulated. Monocular scale is unobservable: the first
//     baseline is 1 (every length is in these units, `scale_free` says so). Stereo: the first
//     frame with min_initialization_inliers stereo points is the first keyframe (metric);
//   tracking: the pose is predicted with constant velocity, the local map's landmarks are
//     projected into the frame and matched to keypoints near their projection (guided by
//     descriptor distance, within projection_search_radius_px times the keypoint's octave
//     scale), then the pose is refined by Gauss-Newton on the reprojection errors with a Huber
//     kernel, observations over the chi-square 95 % bound (5.99 in pixels^2 / octave scale^2)
//     dropped in four rounds. With too few matches, the frame is matched by descriptors against
//     the last keyframes and the pose solved by PnP RANSAC (relocalization after a loss);
//   keyframes: when the tracked landmarks fall under keyframe_tracked_ratio of the last
//     keyframe's, or max_frames_between_keyframes have passed; new landmarks are triangulated
//     against the previous keyframes (descriptor matches under the epipolar constraint, both
//     depths positive, reprojection within the chi-square bound, triangulation angle over
//     min_triangulation_angle_deg) and, stereo, from the keyframe's left-right matches (along
//     the rig's epipolar lines); the last window_keyframes keyframes and their landmarks are
//     refined by bundle adjustment (vision/bundle_adjustment.hpp: the left and the right image's
//     projections, Huber; the window's oldest two keyframes held, they fix the gauge and the monocular scale;
//     stereo holds the oldest only). Observations that stay outliers
//     are removed, landmarks left with fewer than two observations culled;
//   loop closure: every keyframe's ORB descriptors become a bag of words (vision/vocabulary.hpp)
//     in a place database; a new keyframe queries the keyframes at least loop_min_keyframe_gap
//     older, keeping those that score at least as high as its least similar of its three
//     predecessors (ORB-SLAM's threshold). The new keyframe is placed in the candidate's map by
//     PnP RANSAC against the landmarks of the candidate and its two neighbours on each side (the
//     inliers at least 20 % of the descriptor matches), then refined on their projections; a
//     refinement that slides the PnP pose (over 5 % of the depth or 0.05 rad: a periodic
//     texture's shifted fit) is refused. Monocular, the scale between the maps is the median
//     depth ratio of landmarks both have. With loop_min_inliers, the keyframes since the
//     candidate are corrected by a similarity pose graph (consecutive keyframes, their neighbours
//     two apart, earlier loops and the new one; the candidate and older keyframes held; Strasdat
//     et al. 2010), every landmark moved with the keyframe that
//     created it, and tracking goes on from the corrected pose. The edge into a stereo map
//     restart is weak (its pose was only predicted), so a loop pulls that jump straight;
//   standstill: when a large share of the keypoints of the last frame tracked in motion are found
//     again at the same pixels (standstill_share within standstill_pixels: independent of the
//     pose estimate, so objects moving in view cannot fake or hide it), the pose is held at that
//     frame's and no keyframe is added (no baseline: moving objects would be triangulated from
//     pose noise); a slow creep adds up against that frame until it shows. Landmarks whose
//     keypoints move while the camera stands still are on moving objects: they are removed;
//
// RGB-D: as stereo, with the depth image standing in for the right image (create_rgbd).
//
// Frames: the world frame is the first keyframe's camera frame (x right, y down, z forward);
// poses are T_world_camera. Pixels as PinholeCamera (distorted pixels in, distortion handled by
// the projection model). Each frame's pose is kept relative to its reference keyframe, so
// trajectory() reflects the bundle adjustment's corrections.
//
// Failures: track() refuses an image of another size than the configured one, of an
// unsupported type, or a time not after the previous frame's (the frame is skipped, the state
// is unchanged). A frame that cannot be tracked is reported kLost with the reason; tracking
// resumes by relocalization against the recent keyframes, and with stereo a lost frame's own
// stereo points start the map again at its predicted pose (summary().map_restarts).

#include <deque>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/vision/correspondence_filter.hpp"
#include "hanzo/fusion/vision/feature_extractor.hpp"
#include "hanzo/fusion/vision/orb_extractor.hpp"
#include "hanzo/fusion/vision/static_mask.hpp"
#include "hanzo/fusion/vision/vlad.hpp"
#include "hanzo/fusion/vision/vocabulary.hpp"

namespace hanzo::fusion::vision {

struct VisualOdometryConfig {
  /// Features per frame: 2000 as ORB-SLAM uses on KITTI-size images.
  OrbExtractorConfig features = [] {
    OrbExtractorConfig config;
    config.max_features = 2000;
    return config;
  }();
  /// Initialization: essential-matrix inliers needed, and the triangulation angle half of them
  /// must reach.
  int min_initialization_inliers = 100;
  double min_initialization_parallax_deg = 1.0;
  /// Tracking: search radius around a landmark's projection (pixels at octave 0).
  double projection_search_radius_px = 15.0;
  /// The keypoint detector and descriptor; null: ORB with `features` (the default). A learned
  /// extractor (ai::LearnedFeatureExtractor, float descriptors) is matched by Euclidean distance
  /// under max_float_descriptor_distance; its keypoints are all of octave 0 (one scale), and
  /// loop closure needs place recognition for its descriptors (the bag of words is binary).
  std::shared_ptr<const FeatureExtractor> extractor;
  /// Largest Hamming distance of a landmark-keypoint match (bits, binary descriptors).
  int max_descriptor_distance = 64;
  /// Largest Euclidean distance of a match of unit-length float descriptors (0..2).
  double max_float_descriptor_distance = 1.0;
  /// Initialization's two-view matches: null, the ratio test (0.9); else the learned
  /// correspondence filter keeps the mutual matches it classifies as inliers (probability >=
  /// putative_filter_threshold) before the essential-matrix RANSAC.
  std::shared_ptr<const CorrespondenceFilter> putative_filter;
  double putative_filter_threshold = 0.5;
  /// Fewer inliers than this after pose refinement: the frame is lost.
  int min_tracked_landmarks = 15;
  /// Keypoint position noise (pixels at octave 0; octave l has sigma scale_factor^l).
  double pixel_sigma = 1.0;
  /// Standstill: the camera stands still (its pose held, no keyframe) when at least
  /// standstill_share of the keypoints of the last frame tracked in motion are found within
  /// standstill_pixels of where they were, with a close descriptor. Measured: 0.35-0.48 standing
  /// beside passing trucks (KITTI raw 0052), 0.10-0.20 driving at 2.5 m/s, 0.01-0.03 at 11 m/s.
  double standstill_pixels = 1.0;
  double standstill_share = 0.2;
  /// Metric odometry (stereo, RGB-D): not standing still when the frame's refined pose is this
  /// far (m) from the anchor's; driving toward distant features keeps a share of them at their
  /// pixels, which the pixel test alone takes for a standstill.
  double standstill_max_translation = 0.03;
  /// While standing still, a landmark whose keypoint moved more than this (pixels at octave 0)
  /// from where the last frame in motion saw it is on a moving object and is removed.
  double moving_object_pixels = 10.0;
  /// Keyframes.
  double keyframe_tracked_ratio = 0.9;
  int max_frames_between_keyframes = 10;
  double min_triangulation_angle_deg = 1.0;
  /// How many previous keyframes a new keyframe triangulates against.
  int triangulation_keyframes = 2;
  /// Metric odometry (stereo, RGB-D): a pair of keyframes closer than this share of the rig's
  /// baseline is not triangulated (ORB-SLAM's test: the keyframe's own stereo points are the
  /// better depths; nearly coincident keyframes admit only points a few decimetres away, which
  /// are noise, and those tie every following pose to the last one).
  double min_triangulation_baseline_share = 0.5;
  /// Stereo points farther than this many rig baselines are not made landmarks from one frame
  /// (their depth is mostly noise; they can still be triangulated over time).
  double max_stereo_depth_baselines = 100.0;
  /// Local bundle adjustment window (keyframes; about a second of a 10-15 Hz camera, which
  /// holds the monocular scale through turns) and its iterations per pass.
  int window_keyframes = 12;
  int bundle_adjustment_iterations = 20;
  /// Each keyframe's local mapping on its own thread (true: track() returns as soon as the frame
  /// is tracked, a keyframe with its tracked pose) or in the calling thread before track()
  /// returns (false: a keyframe with its adjusted pose). The same map either way (header
  /// comment). The thread cuts the calling thread's time a frame to tracking alone; the
  /// adjusted poses are the more accurate measurements for a filter (bench/RESULTS.md).
  bool local_mapping_thread = true;
  /// Loop closure (see the header comment). `vocabulary` null: the default vocabulary
  /// (Vocabulary::load_default); when it cannot be loaded loop closure is off (logged, and
  /// summary().loop_closure_enabled says so).
  bool loop_closure = true;
  std::shared_ptr<const Vocabulary> vocabulary;
  /// Learned place recognition for learned (float) descriptors: each keyframe's VLAD vector
  /// (vision/vlad.hpp) instead of its bag of words, candidates ranked by cosine similarity with
  /// the same thresholds. The model must be trained on the extractor's descriptors (create()
  /// fails otherwise); null with float descriptors: no loop closure (logged).
  std::shared_ptr<const VladModel> place_model;
  /// Candidates are at least this many keyframes older than the query (recent keyframes look
  /// alike without closing a loop).
  int loop_min_keyframe_gap = 30;
  /// Landmarks of the candidate's map that must agree with the keyframe's placement in it (PnP
  /// inliers, and again after the refinement on their projections) to accept a loop.
  int loop_min_inliers = 30;
  /// Keyframes after a closed loop before the next query (the loop's neighbours would close it
  /// again).
  int loop_cooldown_keyframes = 5;
};

/// Checks every field; the error names the first field out of range.
Status validate(const VisualOdometryConfig& config);

enum class TrackingState { kInitializing, kTracking, kLost };
const char* to_string(TrackingState state);

/// The outcome of one frame.
struct VisualOdometryFrame {
  double time = 0.0;  ///< seconds
  TrackingState state = TrackingState::kInitializing;
  SE3 T_world_camera;       ///< valid when state is kTracking
  int tracked_landmarks = 0;
  bool keyframe = false;
  bool relocalized = false;  ///< tracked again by relocalization after kLost
  bool standing_still = false;  ///< standstill detected: the pose is held
  int moving_landmarks_removed = 0;  ///< landmarks that moved while the camera stood still
  /// A keyframe's local mapping closed a loop (the map and trajectory() were corrected): this
  /// frame's own when mapped inline, else the previous keyframe's, before this frame was tracked.
  bool loop_closed = false;
  std::string reason;        ///< why the frame is kInitializing or kLost
  /// Set on the frame that initialized a monocular map: the time (seconds) of the earlier frame
  /// it was initialized with, the map's first keyframe, whose pose is the world origin
  /// (T_world_camera the identity). That frame was reported kInitializing.
  std::optional<double> map_origin_time;
};

struct VisualOdometrySummary {
  int frames = 0;
  int tracked_frames = 0;
  int lost_frames = 0;
  int keyframes = 0;
  int landmarks = 0;
  int relocalizations = 0;
  int standstill_frames = 0;
  int moving_landmarks_removed = 0;
  int map_restarts = 0;  ///< stereo: tracking lost and the map started again from a stereo frame
  int loop_candidates = 0;  ///< place-recognition candidates checked geometrically
  int loop_closures = 0;    ///< loops accepted and corrected
  bool loop_closure_enabled = false;
  std::string place_recognition;  ///< "bow", "learned" (VLAD), "" when loop closure is off
  bool scale_free = true;  ///< monocular: lengths are in units of the first baseline
  std::string features = "orb";      ///< the extractor's name (FeatureExtractor::name)
  int feature_frames = 0;            ///< frames whose features were extracted (a stereo pair is one)
  double feature_seconds = 0.0;      ///< the time their extraction took (both images of a pair), wall clock
  bool learned_matcher = false;      ///< initialization filtered its matches by the learned correspondence filter
  double mapping_seconds = 0.0;       ///< wall clock of the keyframes' local mapping (on its thread or inline)
  double mapping_wait_seconds = 0.0;  ///< of which tracking waited for (the map not yet ready for the next frame)
  double loop_seconds = 0.0;          ///< of the mapping: place recognition, loop verification and correction
};

class VisualOdometry {
 public:
  /// Fails when the configuration is out of range, the camera's focal lengths are not
  /// positive or the image size is under 64 x 64.
  static Result<std::unique_ptr<VisualOdometry>> create(const PinholeCamera& camera, cv::Size image_size,
                                                        const VisualOdometryConfig& config = {});
  ~VisualOdometry();
  VisualOdometry(const VisualOdometry&) = delete;
  VisualOdometry& operator=(const VisualOdometry&) = delete;

  /// Stereo: the left camera's frame is the odometry's camera frame; the right camera sits at
  /// T_left_right (right camera to left camera; any rig, rectified or not, distortion through
  /// the camera models). Fails as create(), or when the cameras are less than 1 mm apart.
  static Result<std::unique_ptr<VisualOdometry>> create_stereo(const PinholeCamera& left, const PinholeCamera& right, const SE3& T_left_right,
                                                               cv::Size image_size, const VisualOdometryConfig& config = {});

  /// RGB-D: a camera with a depth image registered to it (the same pixel grid): metric from the
  /// first frame, as stereo. Depths are turned into a virtual right camera's keypoints
  /// (ORB-SLAM2's RGB-D as stereo) placed max_depth / max_stereo_depth_baselines to the right, so
  /// depths beyond max_depth (m) are not made landmarks. Fails as create().
  static Result<std::unique_ptr<VisualOdometry>> create_rgbd(const PinholeCamera& camera, cv::Size image_size, const VisualOdometryConfig& config = {},
                                                             double max_depth = 10.0);

  /// Monocular: tracks one image (8-bit grey, BGR or BGRA) taken at `time` (seconds).
  /// static_mask (every track call, optional; static_mask.hpp): the (left) image's moving
  /// objects, where no keypoint is taken, so nothing there is tracked, triangulated or used for
  /// place recognition.
  Result<VisualOdometryFrame> track(double time, const cv::Mat& image, const StaticMask& static_mask = {});
  /// Stereo: a synchronized pair (same size and types as above).
  Result<VisualOdometryFrame> track(double time, const cv::Mat& left, const cv::Mat& right, const StaticMask& static_mask = {});
  /// RGB-D: the image and its depth (the same size; CV_16UC1 millimetres or CV_32FC1 metres,
  /// 0 or NaN where there is none).
  Result<VisualOdometryFrame> track_rgbd(double time, const cv::Mat& image, const cv::Mat& depth, const StaticMask& static_mask = {});

  /// Every tracked frame's time and T_world_camera after the latest bundle adjustment.
  std::vector<std::pair<double, SE3>> trajectory() const;
  /// Keyframe poses (time, T_world_camera) and the map's landmark positions (world frame).
  std::vector<std::pair<double, SE3>> keyframe_poses() const;
  std::vector<Eigen::Vector3d> landmark_positions() const;
  /// The map as a FusionMap layer (msgs::VisualLandmarkLayer): every landmark seen by at least
  /// two keyframes (position, the descriptor of its latest observation, how many keyframes saw
  /// it, and its depth uncertainty depth^2 pixel_sigma / (fx baseline) over the widest baseline
  /// among the cameras that saw it, in map units) and every keyframe (time, T_world_camera, the landmarks it sees), for relocalizing a
  /// camera later (vision/map_relocalizer.hpp).
  msgs::VisualLandmarkLayer landmark_layer(const std::string& camera_name) const;
  VisualOdometrySummary summary() const;

 private:
  struct State;
  explicit VisualOdometry(std::unique_ptr<State> state);
  Result<VisualOdometryFrame> track_frame(double time, const cv::Mat& image, const cv::Mat& right, const StaticMask& static_mask);
  std::unique_ptr<State> state_;
};

}  // namespace hanzo::fusion::vision
