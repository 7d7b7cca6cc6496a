#pragma once
// Session: one agent's whole pipeline (the architecture's "pipeline::Session"): the real-time
// Frontend filter, the LiDAR(-inertial) odometry, the keyframe factor graph, loop closure and
// the map. Every face drives it: `hanzo-fusion run`, the server's sessions, the Python
// `hanzo.fusion.Session`.
//
//   auto session = Session::create(fusion_config, calibration).value();  // mapping: from fusion.mapping
//   session->set_pose_callback([](const msgs::PoseEstimate& pose) { ... });
//   for (...) session->push(sensor, message);      // any sensor, as Frontend::push
//   session->flush();                               // at the end of a log
//   msgs::FusionMap map = session->map();           // points + 2D occupancy of the keyframe scans
//   auto smoothed = session->optimized_trajectory(); // every pose, moved by the optimized graph
//
// Modes (SessionConfig::mode):
//  - kReplay (default): everything happens inside push(), in message order: the same messages
//    and configuration give bit-identical poses, keyframes, trajectories and maps, on any
//    thread count (no worker threads, no background batches, no wall clock).
//  - kRealtime (the server): LiDAR sweeps are registered on a worker thread of the session's
//    own, so the IMU's poses never wait for a registration; a registered sweep is fused when
//    the next message arrives, as a measurement in the past (the Frontend rolls back; it must
//    come within frontend.lag_window). For live data (message times within live_window_s of
//    this machine's clock) a sweep the worker cannot take at once drops the oldest waiting one
//    ("registration_behind": bounded latency, load shedding); recorded data streamed at any
//    speed waits instead. Without an IMU sweeps are registered inside push() (nothing else
//    carries the estimate meanwhile). The graph's full re-optimizations run in the background.
//
// Per message:
//  - 3D LiDAR sweeps of the configured LiDAR sensor (the first `lidar` sensor) are checked
//    (msgs::validate, time after the sensor's previous sweep), moved to the body clock by the
//    LiDAR's calibrated time offset, and wait until the Frontend's IMU has passed the sweep's
//    end; then LidarInertialOdometry registers the sweep against its local map from the
//    filter's motion and fuses the pose into the Frontend. When more than max_waiting_scans
//    wait (the IMU stopped), the oldest is dropped ("imu_behind"; "aligning" before the
//    Frontend's first pose). Without an IMU the sweep moves the Frontend's motion model to
//    its end at once (Frontend::propagate_to) and is registered and deskewed from that
//    prediction; other sensors' messages older than that are fused by the Frontend's rollback.
//  - Sweeps of every further 3D LiDAR get the same input checks, then join the first LiDAR's
//    sweeps (LidarSweepMerger: each point in the first LiDAR's frame by the calibrations, at its
//    own time): one registration over every LiDAR's points. A sweep of the first LiDAR waits
//    for the others to reach its end (at most lidar_merge.wait_s of IMU time; a LiDAR silent
//    for lidar_merge.silent_after_s is not waited for). Their statistics: "fused" when their
//    points joined a sweep of the first LiDAR, "not_fused" when they came too late for any.
//  - A 2D laser scanner (the LiDAR sensor with `type: planar_laser`) goes the same way, but its
//    scans are matched by PlanarLaserOdometry (planar scan matching with its own keyframes,
//    loop closures and planar graph; their poses into the Frontend, a loop closure's jump moves
//    it through the newest keyframe). Its map is ray cast from the planar keyframes at their
//    optimized poses, and optimized_trajectory() is the body at every scan on that graph.
//  - Wheel odometry (the first wheel sensor) is checked against the LiDAR odometry's own motion
//    (WheelSlipMonitor): while the wheels disagree (slip, spin, a wrong scale) their messages
//    are not fused (counted as rejected "slip"); the filter runs on the IMU and the LiDAR.
//  - Camera images (the first camera with intrinsics, a second of the same size makes a stereo
//    pair) go to the visual odometry (vision::VisualOdometry, src/pipeline/camera_odometry.hpp);
//    its camera poses are pose measurements of the Frontend (Frontend::push_pose): without an
//    IMU in the odometry's own world, with an IMU (stereo) placed once in the Frontend's world
//    at the first tracked frame. A monocular camera with an IMU is tracked but not fused.
//    With frontend.type msckf the odometry is visual-inertial (its poses metric with one camera
//    too) and keeps no map, so the Session closes its loops: every map_keyframe_distance /
//    map_keyframe_angle of its motion a tracked left image becomes a place of a
//    vision::VisualLoopDetector, anchored to the newest Frontend keyframe
//    (src/pipeline/visual_loop_closures.hpp); a verified loop adds a loop factor (DCS kernel,
//    the detector's covariance) and the graph corrects the Frontend, whose world the
//    odometry's poses then follow.
//  - A detector's output for a camera (msgs::DetectionsMessage, pushed on the camera's name) is
//    matched to the image of its timestamp; its moving classes (fusion.vision.dynamic_objects)
//    are masked out of that image's features (dynamic_mask.hpp). Once a camera's detector has
//    answered, each of its images waits for its detections until they come or the next image of
//    any camera does (src/pipeline/session_detections.cpp); counts in MappingSummary.
//    With a 3D LiDAR, each sweep's points also take the class of the segmentation pixel they
//    project onto in the nearest output of each camera with a lens model, and points on moving
//    objects are left out of the sweep's registration and the map's layers
//    (src/pipeline/semantic_projection.hpp); the point map fuses the classes per voxel
//    (maps/point_map.hpp), the grid per cell.
//    With fusion.vision.detector, the Session runs that object detector (camera_detector.hpp)
//    on each image of a camera (of the odometry or beside the 3D LiDAR) from which no vision
//    pipeline's output has come, and uses its boxes as pushed ones.
//  - With fusion.mapping.splats, images of the first camera with intrinsics also train 3D
//    Gaussian splats (session_splats.hpp) at the Session's poses, anchored to keyframes so that
//    they follow the graph; seeded at the map keyframes' points. Replay trains inside push()
//    (deterministic), realtime on a worker thread of their own with a bounded share of a core.
//  - Everything else goes to Frontend::push (same checks, same errors).
//  - Keyframes of the Frontend (frontend.keyframe_interval) become nodes of a KeyframeGraph
//    (between factors from the filter's relative motion; with an IMU and a camera (msckf) or a
//    3D LiDAR, IMU preintegration and the visual landmarks' or the LiDAR odometry's factors,
//    the filter's relative motion a weak anchor); after each push the graph is updated
//    and corrects the Frontend (at loop closures only where it holds what the filter fused). The LiDAR odometry follows the correction (its frame moves with
//    the Frontend's world).
//  - Map keyframes: the first registered sweep after a Frontend keyframe, when the LiDAR moved
//    map_keyframe_distance / map_keyframe_angle since the previous map keyframe, is kept
//    (deskewed points, sensor frame) with its pose relative to that Frontend keyframe. It goes
//    into the map (maps::MapBuilder: point map + 2D occupancy by default; with its sweep and
//    pose into the map's lidar_keyframes, which pipeline/session_merge.hpp joins across
//    sessions) and into the loop closure detector (lidar/loop_closure.hpp: Scan Context +
//    registration); one at a place
//    the map already has (a revisit, LoopClosureConfig::covered_distance) is searched for a
//    loop, then goes into the grids only and is not kept (memory stays flat on a route driven
//    again and again). A verified loop
//    adds a between factor under a DCS kernel (KeyframeGraph::add_loop_closure), the graph
//    runs a full batch and corrects the Frontend, and every map keyframe whose keyframe moved
//    is moved in the map (the point map exactly; occupancy keeps what was integrated).
//  - Manual loop closures (the server's POST /v1/sessions/{id}/loop-closure): close_loop().
//  - GNSS fixes the filter fused (Frontend::set_gnss_callback) become GPS factors on the newest
//    Frontend keyframe (gnss_factors), their lever arm carried through the body's motion from
//    the keyframe to the fix, so that the graph's corrections agree with GNSS instead of
//    pulling against it (and GNSS bounds the drift of poses a loop closure moves). With a 3D
//    LiDAR and an IMU the graph holds the fixes alone and the Frontend follows it
//    (frontend_follows_graph).
//
// Frames: world = the Frontend's world (ENU at the datum when GNSS or a datum is configured).
// Units m, s, rad. Limits: the first LiDAR paces the merged sweeps (without it the others are
// not registered); after a relocalization (world = the map's
// frame) GNSS fixes are no longer added to the graph.
// Not thread-safe: one thread at a time (the server serializes per session).
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/lidar/loop_closure.hpp"
#include "hanzo/fusion/lidar/map_localization.hpp"
#include "hanzo/fusion/maps/map_builder.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/pipeline/keyframe_graph.hpp"
#include "hanzo/fusion/pipeline/lidar_inertial_odometry.hpp"
#include "hanzo/fusion/pipeline/lidar_sweep_merger.hpp"
#include "hanzo/fusion/pipeline/planar_laser_odometry.hpp"
#include "hanzo/fusion/pipeline/frontend.hpp"
#include "hanzo/fusion/pipeline/sensor_health.hpp"
#include "hanzo/fusion/pipeline/wheel_slip_monitor.hpp"
#include "hanzo/fusion/vision/map_relocalizer.hpp"
#include "hanzo/fusion/vision/static_mask.hpp"

namespace cv {
class Mat;
}

namespace hanzo::fusion::pipeline {

class CameraOdometry;
class CameraDetector;
class SemanticProjection;
class LidarInertialFactors;
class BodyImu;
class SessionSplats;
class VisualLoopClosures;

enum class SessionMode { kReplay, kRealtime };
std::string_view to_string(SessionMode mode);  // "replay", "realtime"

struct SessionConfig {
  /// See the header comment: kReplay is deterministic, kRealtime bounds the latency.
  SessionMode mode = SessionMode::kReplay;
  /// Threads of the LiDAR odometry (1: the calling thread; <= 0: every core). Results do not
  /// depend on it (bit for bit).
  int num_threads = 1;
  /// false: the Frontend alone (no LiDAR odometry, graph, loop closure or map); sweeps are
  /// counted as not fused.
  bool mapping = true;
  LidarInertialOdometryConfig lidar_odometry;
  /// Further 3D LiDARs joined to the first one's sweeps (its min_range / max_range are replaced
  /// by lidar_odometry's).
  LidarSweepMergerConfig lidar_merge;
  /// A 2D laser scanner (a lidar sensor with `type: planar_laser`): scan matching, keyframes and
  /// loop closures of its own planar graph (planar_laser_odometry.hpp) instead of the 3D LiDAR
  /// odometry, Scan Context and the keyframe graph's LiDAR factors.
  PlanarLaserOdometryConfig planar_laser;
  /// The backend; its batch_on_loop_closure is forced on (a loop closure must correct the
  /// map and the Frontend at once), smoother.background_batch is set by the mode.
  KeyframeGraphConfig backend;
  bool loop_closure = true;
  /// GNSS fixes the filter fused become GPS factors of the keyframe graph.
  bool gnss_factors = true;
  /// Radar ego velocities and wheel speeds the filter fused become velocity factors
  /// (graph::BodyVelocityFactor) on the keyframe within velocity_max_time_offset_s of them, one
  /// per sensor and keyframe, in graphs that estimate keyframe velocities (the LiDAR- and
  /// visual-inertial ones). The body's velocity change over the offset is taken as noise:
  /// velocity_acceleration_sigma (m/s^2) times the offset.
  bool velocity_factors = true;
  /// Where the LiDAR-inertial graph holds the GNSS fixes with their correlated error
  /// (gnss_factors, backend.gnss_error_correlation_s > 0, a 3D LiDAR and an IMU), the graph
  /// owns the world: once the heading is known the filter passes the fixes it would fuse
  /// (past its gate) to the graph without fusing them itself (Frontend::
  /// set_gnss_positions_to_backend), the graph corrects the Frontend after every update, the
  /// LiDAR odometry's map frame stays where the filter had it then and moves with those
  /// corrections (LidarInertialOdometry::hold_map_frame), and in replay a full batch runs every
  /// follow_batch_interval_s of keyframe time (backend.batch_interval_s). Each fix is counted
  /// once, and the real-time poses get the graph's world instead of the filter's. false: the
  /// filter fuses the fixes and the graph corrects it at loop closures only.
  bool frontend_follows_graph = true;
  double follow_batch_interval_s = 5.0;
  double velocity_max_time_offset_s = 0.03;
  double velocity_acceleration_sigma = 2.0;
  /// frontend.type msckf: the keyframe graph holds IMU preintegration and landmark projection
  /// factors (visual_inertial_factors.hpp), the odometry's relative motions only as a weak anchor.
  /// Such a graph corrects the Frontend at loop closures only, and its smoother re-optimizes at
  /// least the newest 400 variables (several keyframes with their landmarks) and at most 2 factor
  /// hops around a new keyframe; Levenberg-Marquardt starts from a trust region of 1e4; loop
  /// closures run their batch at most every 10 s (backend.loop_batch_interval_s).
  bool visual_inertial_factors = true;
  /// The visual-inertial keyframe graph (frontend.type msckf) updates on a thread of its own
  /// while the next frames are tracked: an update starts after the push that added a keyframe's
  /// factors and is waited for where the session next reads or changes the graph (the next
  /// keyframe, a loop closure, a query, flush). Updates that may correct the Frontend (a loop
  /// closure) run inside push(). The estimates are those of updating inside push(), in both
  /// modes. false: every update inside push().
  bool backend_thread = true;
  /// The visual-inertial graph's sliding window (backend.window_keyframes; the configuration's
  /// fusion.mapping.visual_inertial_window): 40 keyframes (20 s
  /// at the msckf keyframe interval); older keyframes keep their poses only. 0: every keyframe's
  /// variables and landmarks stay (memory and loop-closure batches grow with the flight).
  /// Measured against keeping everything in bench/RESULTS.md.
  int visual_inertial_window_keyframes = 40;
  /// A 3D LiDAR and an IMU: the keyframe graph holds IMU preintegration factors and the LiDAR
  /// odometry's relative motions with their registration covariance (lidar_inertial_factors.hpp),
  /// the filter's relative motions only as a weak anchor; such a graph corrects the Frontend at
  /// loop closures only. false: between factors from the filter's relative motion.
  bool lidar_inertial_factors = true;
  lidar::LoopClosureConfig loop;
  double loop_translation_sigma = 0.05;  ///< m, loop closure factors (detected and manual)
  double loop_rotation_sigma = 0.005;    ///< rad
  double map_keyframe_distance = 1.0;    ///< m of LiDAR motion between map keyframes (camera motion between visual places)
  double map_keyframe_angle = 0.2;       ///< rad
  /// Map layers. Default: 0.2 m points (keyframes kept at 0.1 m) and a 0.1 m 2D occupancy grid.
  maps::MapBuilderConfig map = default_map();
  std::size_t max_waiting_scans = 5;     ///< sweeps waiting for the IMU; beyond, the oldest is dropped
  /// kRealtime: message times within this of the machine's clock are live data (s).
  double live_window_s = 10.0;
  /// Keep every emitted pose (64 bytes each) for optimized_trajectory(); the server does not.
  bool keep_trajectory = true;
  /// Wheels against the LiDAR's motion (with a 3D LiDAR and wheel odometry).
  WheelSlipConfig wheel_slip;

  Status validate() const;
  static maps::MapBuilderConfig default_map();
  /// The defaults with the configuration's fusion.mapping block applied.
  static SessionConfig from(const config::FusionConfig& config);
};

/// A manual loop closure between two Frontend keyframes (ids from the keyframe callback).
/// With T_from_to the factor is added as given (a known relative pose, e.g. a surveyed
/// marker); without it, both keyframes must be map keyframes (have a scan) and keyframe
/// `to` is registered against the scans around `from` starting at the graph's relative pose.
/// With neither keyframe, the newest map keyframe is searched against all older ones (the
/// detector's rules: Scan Context candidate within the search radius, then registration).
struct LoopClosureRequest {
  std::optional<uint64_t> from_keyframe;
  std::optional<uint64_t> to_keyframe;
  std::optional<SE3> T_from_to;
  /// Over the tangent (rho, phi) of T_from_to; default: loop_translation/rotation_sigma.
  std::optional<Eigen::Matrix<double, 6, 6>> covariance;
};

struct LoopClosureOutcome {
  uint64_t from_keyframe = 0;
  uint64_t to_keyframe = 0;
  SE3 T_from_to;
  bool registered = false;        ///< verified by registration (else given by the caller)
  double inlier_rmse = 0.0;       ///< m, when registered
  double inlier_fraction = 0.0;
  double correction_m = 0.0;      ///< how far the latest keyframe moved
};

/// Relocalization against a known map (lidar::MapLocalizer over its point layer): where the
/// session is in the map's frame. Without a guess the whole map is searched.
struct RelocalizationRequest {
  std::optional<SE3> T_map_body_guess;  ///< the body's pose in the map now (e.g. from an operator)
  double linear_window = 5.0;           ///< m, searched +- around the guess
  double angular_window = 0.5;          ///< rad, +- around the guess's heading
};

struct RelocalizationOutcome {
  SE3 T_map_world;               ///< how the session's world frame was moved onto the map's
  SE3 T_map_lidar;               ///< the localized sweep (the newest map keyframe's)
  uint64_t keyframe_id = 0;      ///< the Frontend keyframe the correction was applied at
  lidar::MapLocalization localization;
};

/// Camera relocalization against a saved visual landmark map (a FusionMap's visual_landmarks
/// layer, made by a session with cameras; vision::MapRelocalizer). Each of the newest `frames`
/// images of the left camera that the Session has a pose for is placed in the map on its own;
/// each placement says where the session's world lies in the map (T_map_world =
/// T_map_camera T_body_camera^-1 T_world_body^-1 at the image's time). The placement that the
/// most placements (itself included) agree with, within agreement_m and agreement_rad, wins
/// (ties: the most inliers), when at least `min_agreeing_frames` agree: one image can be placed
/// wrongly on a repeated texture, several images from different viewpoints rarely agree on the
/// same wrong place.
struct CameraRelocalizationRequest {
  int frames = 3;               ///< newest left images tried (the Session keeps the last kRecentCameraImages)
  int min_agreeing_frames = 2;  ///< placements that must agree (1..frames)
  double agreement_m = 0.3;     ///< m, between the worlds two placements give
  double agreement_rad = 0.05;  ///< rad, the same
  /// Candidates, inliers and search radius of each placement. Null extractor: ORB for an ORB
  /// map, the session's own extractor for a map of its learned features.
  vision::MapRelocalizerConfig relocalizer;
};

/// One image's placement in a camera relocalization.
struct CameraPlacement {
  Timestamp time;             ///< the image's (body clock)
  bool placed = false;        ///< the relocalizer found a pose
  std::string reason;         ///< why not, when not placed
  SE3 T_map_camera;           ///< the image's camera in the map (placed)
  SE3 T_map_world;            ///< the session's world in the map by this image (placed)
  int inliers = 0;
  int map_keyframe = -1;      ///< the map keyframe whose landmarks placed it
  double place_score = 0.0;   ///< that keyframe's place-recognition score
  bool agrees = false;        ///< within the agreement bounds of the accepted placement
};

struct CameraRelocalizationOutcome {
  SE3 T_map_world;            ///< how the session's world frame was moved onto the map's
  uint64_t keyframe_id = 0;   ///< the Frontend keyframe the correction was applied at
  int agreeing_frames = 0;
  std::string place_recognition;  ///< "bow", "learned" or "matches" (vision::MapRelocalization)
  double correction_m = 0.0;  ///< how far the newest keyframe moved
  std::vector<CameraPlacement> placements;  ///< newest image first
};

struct MappingSummary {
  uint64_t scans_received = 0;
  uint64_t scans_registered = 0;
  uint64_t scans_refused = 0;     ///< refused by the odometry or dropped waiting for the IMU
  uint64_t degenerate_scans = 0;
  uint64_t weather_degraded_scans = 0;
  uint64_t map_keyframes = 0;
  /// Map keyframes offered at places the map already had (LoopClosureConfig::covered_distance):
  /// searched for a loop, their sweep put into the grids only, not kept.
  uint64_t map_revisits = 0;
  uint64_t graph_keyframes = 0;
  /// Landmarks of the visual-inertial keyframe graph (frontend.type msckf) and their projections.
  uint64_t graph_landmarks = 0;
  uint64_t graph_projections = 0;
  /// Keyframes the LiDAR-inertial keyframe graph links to the previous one by IMU
  /// preintegration and by the LiDAR odometry's relative motion (lidar_inertial_factors).
  uint64_t graph_imu_factors = 0;
  uint64_t graph_lidar_factors = 0;
  uint64_t loop_candidates = 0;
  uint64_t loop_closures = 0;     ///< detected and verified
  uint64_t manual_loop_closures = 0;
  uint64_t map_version = 0;       ///< increases with every change of the map
  std::size_t map_memory_bytes = 0;
  double last_registration_ms = 0.0;
  double last_correction_m = 0.0; ///< the backend's last correction of the latest keyframe
  uint64_t relocalizations = 0;   ///< successful relocalize() calls
  uint64_t gnss_factors = 0;      ///< GNSS fixes added to the keyframe graph
  uint64_t graph_velocity_factors = 0;  ///< radar and wheel velocities added to the keyframe graph
  uint64_t wheel_slip_episodes = 0;   ///< times the wheels began to disagree with the LiDAR
  uint64_t wheel_messages_withheld = 0;  ///< wheel messages not fused because of it
  /// Cameras (visual odometry): frames tracked / lost, its keyframes and landmarks, standstill
  /// frames, visual loop closures, and whether its lengths are scale-free (monocular) or metric
  /// (stereo).
  uint64_t camera_frames_tracked = 0;
  uint64_t camera_frames_lost = 0;
  uint64_t visual_keyframes = 0;
  uint64_t visual_landmarks = 0;
  uint64_t camera_standstill_frames = 0;
  uint64_t visual_loop_closures = 0;
  bool visual_scale_free = false;
  /// Left camera images too dark, washed out by glare, or blurred by motion
  /// (vision/image_quality.hpp); such frames may still be tracked.
  uint64_t camera_dark_frames = 0;
  uint64_t camera_glare_frames = 0;
  uint64_t camera_motion_blur_frames = 0;
  /// The cameras' feature stage: its detector ("orb"; "shi-tomasi" in the visual-inertial
  /// odometry; or a learned model, "aliked-t16", ...: fusion.vision.features), its mean time per
  /// frame (ms, wall clock: extraction, or the visual-inertial tracker's detection and optical
  /// flow), and whether the learned correspondence filter matched the first views
  /// (fusion.vision.matcher learned). Empty / 0 / false without cameras.
  std::string camera_features;
  double camera_feature_ms = 0.0;
  /// Mean wall-clock time of the visual odometry's local mapping per keyframe (ms: right-image
  /// features, triangulation, bundle adjustment, loop closure; fusion.vision.local_mapping_thread
  /// runs it beside tracking); 0 for the visual-inertial odometry and without cameras.
  double camera_mapping_ms = 0.0;
  bool camera_learned_matcher = false;
  /// A detector's output on the cameras (msgs::DetectionsMessage, fusion.vision.dynamic_objects):
  /// messages received, refused (invalid, another image size, not a tracked camera), matched
  /// to their image, late (their image was tracked without them), images that waited for
  /// detections that never came; images whose features a moving object's mask limited, the
  /// objects masked, and the mean share of a masked image's pixels.
  uint64_t detections_received = 0;
  /// Images the Session's own detector (fusion.vision.detector) ran on, those it failed on, and
  /// its mean time per image (ms); its detections count as received too.
  uint64_t detections_computed = 0;
  uint64_t detector_failures = 0;
  double detector_ms = 0.0;
  uint64_t detections_refused = 0;
  uint64_t detections_matched = 0;
  uint64_t detections_late = 0;
  uint64_t images_without_detections = 0;
  uint64_t images_masked = 0;
  uint64_t dynamic_objects_masked = 0;
  double masked_image_share = 0.0;
  /// LiDAR points a segmentation labelled, and those left out of the map on a moving object
  /// (a 3D LiDAR and cameras with a lens model).
  uint64_t lidar_points_labelled = 0;
  uint64_t lidar_points_masked = 0;
  /// Point-map keyframe points left out as on objects that moved away: later (or earlier) scans
  /// saw through their place (fusion.mapping.remove_moving_points; maps/point_map.hpp).
  uint64_t map_points_moving_removed = 0;
  /// The visual odometry's loop-closure candidates: "bow", "learned" (VLAD), "" when it closes
  /// no loops (fusion.vision.place_recognition).
  std::string visual_place_recognition;
  /// Gaussian splats trained from the camera (fusion.mapping.splats; session_splats.hpp): views,
  /// optimizer steps, Gaussians now, images not used (no pose, unreadable); zero when off.
  uint64_t splat_views = 0;
  uint64_t splat_iterations = 0;
  uint64_t splat_gaussians = 0;
  uint64_t splat_images_skipped = 0;
};

/// A pose at a time (body in the world frame).
struct StampedPose {
  Timestamp timestamp;
  SE3 T_world_body;
};

class Session {
 public:
  using KeyframeCallback = std::function<void(const msgs::Keyframe&)>;
  using MapUpdateCallback = std::function<void(const msgs::MapUpdate&)>;
  using ScanCallback = std::function<void(const LidarInertialOdometry::RegisteredScan&)>;

  /// Fails as Frontend::create does, or on an invalid SessionConfig. Without a SessionConfig
  /// the settings come from the configuration (SessionConfig::from(config)).
  static Result<std::unique_ptr<Session>> create(const config::FusionConfig& config, const calib::Calibration& calibration);
  static Result<std::unique_ptr<Session>> create(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                 SessionConfig session_config);
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  /// One message of the named sensor. Rejections as Frontend::push; a LiDAR sweep is refused
  /// as invalid, duplicate or out_of_order and otherwise accepted (it may
  /// still fail to register later: counted in mapping_summary and the sensor's statistics).
  /// Taken by value: a sweep moved in is kept without a copy while it waits for the IMU.
  PushStatus push(std::string_view sensor, msgs::SensorMessage message);
  /// Fuses what waits (Frontend::flush) and registers the sweeps the IMU has passed.
  void flush();
  /// Errors start with the reason: "invalid: ..." (a bad request), "not_found: ..." (unknown
  /// keyframe, keyframe without a scan, no loop found by the search), "not_verified: ..." (the
  /// registration refused the loop: RMSE, overlap, degeneracy). Nothing changes then.
  Result<LoopClosureOutcome> close_loop(const LoopClosureRequest& request);
  /// Localizes the newest map keyframe's sweep (with the two before it) in `map` and moves the
  /// Session's world onto the map's frame: poses, keyframes and the Session's own map come in
  /// the map's frame from then on (a jump of T_map_world, in one Frontend correction). The
  /// keyframe graph restarts at the next keyframe (anchored there with the filter's
  /// covariance); older map keyframes stay where the relocalization put them and loops to
  /// them are no longer closed. Errors start with the reason: "invalid: ..." (a non-finite
  /// guess or window), "not_ready: ..." (no map keyframe or Frontend keyframe yet),
  /// "not_found: ..." (the localizer found no pose that verifies; its reason follows).
  /// Nothing changes then.
  Result<RelocalizationOutcome> relocalize(const lidar::MapLocalizer& map, const RelocalizationRequest& request);
  /// Left images kept for camera relocalization (the newest).
  static constexpr int kRecentCameraImages = 8;
  /// What the Session can relocalize with: a LiDAR it maps (3D or planar), cameras with visual odometry.
  bool maps_lidar_sweeps() const { return maps_lidar(); }
  bool has_camera_odometry() const { return camera_odometry_ != nullptr; }
  /// Places the newest left-camera images in a saved visual landmark map (the request's
  /// header comment) and, when enough of them agree, moves the Session's world onto the map's
  /// frame as the LiDAR relocalization does (one Frontend correction; the keyframe graph
  /// restarts at the next keyframe; the visual odometry's poses and landmarks follow). Errors
  /// start with the reason: "invalid: ..." (a request out of range, a map without landmarks or
  /// keyframes, of other features than the session's, a monocular session without an IMU,
  /// whose lengths have no metric scale), "not_ready: ..." (no camera, no posed image or no
  /// Frontend keyframe yet), "not_found: ..." (too few images placed, or placed in agreement;
  /// each placement's reason follows). Nothing changes then.
  Result<CameraRelocalizationOutcome> relocalize(const msgs::VisualLandmarkLayer& map, const CameraRelocalizationRequest& request);

  /// The map's layers (points, occupancy; the LiDAR keyframes; the cameras' landmarks; the
  /// Gaussian splats trained so far with fusion.mapping.splats) with version = map_version and
  /// provenance.algorithm set ("pipeline/session"); other metadata empty. The splats change
  /// without map_version.
  msgs::FusionMap map() const;

  /// Seeds the session with a saved map of the same session made by another process (a server
  /// replica taking the session over from a failed replica); call after Frontend::resume and
  /// before the first sweep. The map's LiDAR keyframes go into this session's map layers and into
  /// the lidar_keyframes of every map() it writes; those within the odometry's map range
  /// (lidar_odometry.odometry.map.max_distance) of the map's newest keyframe go into the LiDAR
  /// odometry's local map, where the first sweeps register against them. They take no part in
  /// loop closures. Fails, changing nothing, when the map has no LiDAR keyframes, the session has
  /// no 3D LiDAR odometry, or the session has received a sweep.
  Status restore_map(const msgs::FusionMap& map);
  /// The Frontend's summary with the LiDAR sensor's counters filled in.
  SessionSummary summary() const;
  MappingSummary mapping_summary() const;
  /// Optimized T_world_body of a Frontend keyframe known to the graph.
  std::optional<SE3> keyframe_pose(uint64_t keyframe_id) const;
  /// Every pose emitted so far (keep_trajectory), moved onto the graph's current estimate: the
  /// correction of a pose between two keyframes (optimized keyframe pose times the keyframe's
  /// pose as the filter had it, before any correction, inverted) is interpolated on SE3 between
  /// theirs by time; before the first and after the last keyframe theirs holds. This is the
  /// smoothed trajectory of an offline run: GNSS factors, loop closures and later LiDAR poses
  /// act on every pose, not only on those after the correction. Empty without keep_trajectory.
  std::vector<StampedPose> optimized_trajectory() const;
  /// Every configured sensor's health now (sensor_health.hpp), in configuration order.
  std::vector<SensorHealth> health() const;
  /// The changes of health so far, in time order (evaluated every 0.2 s of data; the first
  /// entry per sensor is its state once the Frontend emits poses).
  const std::vector<HealthChange>& health_changes() const { return health_changes_; }
  SessionMode mode() const { return config_.mode; }

  /// Called for every PoseEstimate, in time order (Frontend::set_pose_callback), with every
  /// sensor's health as last evaluated (status.sensor_health; empty before the first poses).
  void set_pose_callback(Frontend::PoseCallback callback) { pose_callback_ = std::move(callback); }
  /// Called for every measurement update (Frontend::set_innovation_callback).
  void set_innovation_callback(Frontend::InnovationCallback callback) { innovation_callback_ = std::move(callback); }
  /// Every Frontend keyframe as emitted.
  void set_keyframe_callback(KeyframeCallback callback) { keyframe_callback_ = std::move(callback); }
  /// Every LiDAR sweep registered and fused (its estimate, pose, covariance and timing), after
  /// the Frontend took its pose.
  void set_scan_callback(ScanCallback callback) { scan_callback_ = std::move(callback); }
  /// New map keyframes (added_points in the world frame) and, after loop closures, the whole
  /// corrected point map (full_replacement).
  void set_map_update_callback(MapUpdateCallback callback) { map_update_callback_ = std::move(callback); }

  Frontend& frontend() { return *frontend_; }
  const Frontend& frontend() const { return *frontend_; }

 private:
  struct MapKeyframe {
    Timestamp time;            ///< the sweep's
    uint64_t anchor = 0;       ///< the Frontend keyframe
    SE3 T_anchor_lidar;        ///< the sweep's pose relative to the anchor's body
    SE3 T_world_lidar;         ///< where the map has it now
  };
  Session(std::unique_ptr<Frontend> frontend, SessionConfig config, std::string lidar_sensor, bool planar_laser,
          const calib::SensorCalibration& lidar_calibration, std::string wheel_sensor, const calib::SensorCalibration& wheel_calibration);
  /// Feeds the slip monitor; false when the wheels disagree with the LiDAR (not fused then).
  bool wheels_agree(const msgs::WheelOdometryMessage& wheels);
  PushStatus push_message(std::string_view sensor, msgs::SensorMessage message);
  void flush_pipeline();
  PushStatus push_scan(msgs::PointCloudMessage scan);
  /// A camera image for the visual odometry (camera_odometry.hpp), its pose into the Frontend.
  PushStatus push_image(std::string_view sensor, const msgs::SensorMessage& message);
  /// A detector's output for an image of a camera the odometry takes: matched to its image
  /// (waiting, or the next one of that camera) by timestamp.
  PushStatus push_detections(std::string_view sensor, const msgs::DetectionsMessage& detections);
  /// push_detections() of a vision pipeline's output (`computed` false: that camera's images are
  /// no longer given to fusion.vision.detector) or of the Session's own detector.
  PushStatus use_detections(std::string_view sensor, const msgs::DetectionsMessage& detections, bool computed);
  /// fusion.vision.detector on a camera image whose camera has no vision pipeline's output.
  void detect_objects(std::string_view sensor, const msgs::SensorMessage& message);
  /// Tracks the images waiting for their detections taken before `time` (all with none).
  void release_waiting_images(std::optional<Timestamp> before);
  /// Whether an image of `sensor` at `time` waits for its detections: the camera's detector
  /// has answered before, none of `time` is here yet, and the configuration waits.
  bool wait_for_detections(std::string_view sensor, Timestamp time);
  /// The static mask (dynamic_mask.hpp) from the detections of the image's time, counted;
  /// empty when none came or nothing moves in them.
  vision::StaticMask static_mask_for(const std::string& sensor, const msgs::ImageMessage& image);
  /// An image past push_image's checks, with the detections of its time (if any came).
  PushStatus track_image(const std::string& sensor, const msgs::ImageMessage& image);
  class RegistrationWorker;
  /// final: at flush, the other LiDARs are not waited for (nothing more comes).
  void register_ready_scans(bool final = false);
  /// Fuses what the worker registered (kRealtime).
  void take_registered();
  void on_registered(Result<LidarInertialOdometry::RegisteredScan> registered);
  /// Feeds the slip monitor the LiDAR's motion since the previous registered sweep (none: the
  /// first); `reliable` false when the geometry or weather made it doubtful.
  void check_wheels(Timestamp sweep_time, const std::optional<SE3>& T_previous_current, bool reliable);
  /// The sweep as a map keyframe anchored to the newest Frontend keyframe.
  /// point_classes: empty or a segmentation class per point (label_sweep).
  void add_map_keyframe(Timestamp time, const SE3& T_world_lidar, const std::vector<Eigen::Vector3f>& points, const std::vector<uint16_t>& point_classes);
  /// Looks for a loop closing at the loop closure detector's newest keyframe (kept or a
  /// revisit); a verified one becomes a loop factor.
  void detect_lidar_loop();
  /// T_world_lidar of map keyframe k by the graph's current estimate.
  /// The loop closure detector's keyframe k: map_keyframes_[k], or the pending revisit.
  const MapKeyframe& map_keyframe(std::size_t k) const;
  SE3 map_keyframe_pose(std::size_t k) const;
  Status add_loop_factor(uint64_t from, uint64_t to, const SE3& T_from_to, const std::optional<Eigen::Matrix<double, 6, 6>>& covariance);
  /// Runs the backend (on the backend thread where backend_thread_); moves the map keyframes
  /// whose keyframe moved (follow_graph).
  void update_backend();
  /// The graph, once a running backend update has finished (its result applied: the non-const
  /// one; marked as changed, so that the next update_backend() runs).
  KeyframeGraph& graph();
  const KeyframeGraph& graph() const;
  void wait_for_backend() const;
  /// What an update's result changes in the session (landmarks forgotten, map keyframes moved).
  void finish_backend_update(Result<KeyframeGraphUpdate> update);
  void follow_graph();
  /// Moves map keyframes (the map builder's number: restored keyframes, then map_keyframes_ -> T_world_lidar) in the map and publishes the corrected map.
  void move_map_keyframes(const std::map<uint64_t, SE3>& moved);
  /// Moves the Session's world onto a map's frame (both relocalizations): the Frontend's belief
  /// of its newest keyframe corrected by T_map_world, the map keyframes moved, a fresh graph
  /// from the next keyframe. Returns how far the newest keyframe moved (m).
  Result<double> move_world_onto_map(const SE3& T_map_world);
  void count_refused(Rejection reason);
  /// The monocular map's first view (reported initializing at origin_time s) fused at the world
  /// origin, before the frame that made the map.
  void fuse_map_origin(double origin_time, const Eigen::Matrix<double, 6, 6>& covariance);
  /// A tracked left image offered as a visual place; a verified loop becomes a loop factor.
  void add_visual_place(Timestamp time, int rig, const cv::Mat& image, const vision::StaticMask& static_mask, const SE3& T_odometry_body);
  /// Records the health changes since the last evaluation (every 0.2 s of data time).
  void track_health();
  /// A fused GNSS fix as a GPS factor on the newest keyframe (gnss_factors).
  void add_gnss_factor(const FusedGnssFix& fix);
  /// Fused sensor velocities as velocity factors on the newest keyframe near them in time
  /// (velocity_factors): when a velocity comes, and for those of the last moments when a
  /// keyframe comes.
  void add_velocity_factor(const FusedVelocity& velocity);
  void attach_recent_velocities();

  std::unique_ptr<Frontend> frontend_;
  SessionConfig config_;
  std::string lidar_sensor_;
  SE3 T_body_lidar_;
  Duration lidar_time_offset_;            ///< t_body = t_lidar + offset (calibration)
  std::string wheel_sensor_;              ///< checked against the LiDAR; empty without both
  SE3 T_body_wheels_;
  Duration wheel_time_offset_;
  WheelSlipMonitor slip_monitor_;
  std::optional<Timestamp> last_sweep_time_;  ///< the previous registered sweep's middle
  std::unique_ptr<KeyframeGraph> graph_;  ///< replaced by a fresh one at a relocalization
  bool restart_graph_ = false;  ///< the next keyframe starts the graph (after a relocalization)
  bool backend_thread_ = false;  ///< SessionConfig::backend_thread with a visual-inertial graph
  bool graph_touched_ = false;   ///< graph() was used since the last update started
  mutable std::future<Result<KeyframeGraphUpdate>> backend_update_;     ///< the running update
  mutable std::optional<Result<KeyframeGraphUpdate>> backend_result_;   ///< finished, not yet applied
  std::optional<LidarInertialOdometry> odometry_;
  /// True while the graph holds the GNSS fixes and corrects the Frontend after every update
  /// (SessionConfig::frontend_follows_graph with a LiDAR-inertial graph and GNSS).
  bool follows_graph_ = false;
  /// The LiDAR-inertial graph's factors (lidar_inertial_factors) and the IMU they integrate.
  std::unique_ptr<LidarInertialFactors> lidar_factors_;
  std::deque<FusedVelocity> recent_velocities_;             // the last velocity_max_time_offset_s
  std::map<std::string, uint64_t> velocity_keyframe_;       // sensor -> keyframe of its last factor
  std::unique_ptr<BodyImu> body_imu_;
  std::string imu_sensor_;
  std::optional<PlanarLaserOdometry> planar_;  ///< instead of odometry_ for a planar_laser sensor
  /// Whether sweeps of lidar_sensor_ go through a LiDAR pipeline (3D or planar) here.
  bool maps_lidar() const { return odometry_.has_value() || planar_.has_value(); }
  /// Matches and fuses one planar scan; its counts as a registered sweep's.
  void on_planar_scan(const msgs::PointCloudMessage& scan);
  std::unique_ptr<RegistrationWorker> worker_;  ///< kRealtime
  lidar::LoopClosureDetector loop_closures_;
  maps::MapBuilder map_builder_;
  struct WaitingScan {
    msgs::PointCloudMessage scan;
    Timestamp end;  ///< the latest point time (computed once: checked on every message)
  };
  std::deque<WaitingScan> waiting_scans_;
  /// The other 3D LiDARs' sweeps, joined to the first's (none with one LiDAR).
  std::optional<LidarSweepMerger> merger_;
  struct SecondaryLidar {
    Duration time_offset;         ///< t_body = t_lidar + offset
    std::optional<Timestamp> last_time;
    SensorStatistics statistics;  ///< input checks (fused / not_fused come from the merger)
  };
  std::vector<SecondaryLidar> secondary_lidars_;  ///< as merger_'s secondaries
  PushStatus push_secondary_scan(std::size_t index, msgs::PointCloudMessage scan);
  std::optional<Timestamp> first_pose_time_;  ///< the Frontend's first pose seen
  /// How long a sweep may wait for the worker now (kRealtime: none for live data, else unbounded).
  std::optional<std::chrono::nanoseconds> registration_wait_limit(Timestamp now_in_data) const;
  std::optional<Timestamp> last_scan_time_;
  std::optional<msgs::Keyframe> latest_keyframe_;   ///< the newest Frontend keyframe
  SE3 latest_keyframe_uncorrected_;                 ///< its pose before the Frontend's corrections
  std::vector<MapKeyframe> map_keyframes_;
  std::vector<msgs::LidarKeyframe> restored_keyframes_;  ///< restore_map()'s, before map_keyframes_
  /// The newest map keyframe offered when it was a revisit: the loop closure detector keeps it
  /// (as keyframe map_keyframes_.size()) until the next one is offered, for close_loop().
  std::optional<MapKeyframe> pending_revisit_;
  std::map<uint64_t, std::size_t> map_keyframe_of_;  ///< Frontend keyframe id -> map keyframe
  std::optional<uint64_t> last_anchor_;
  std::optional<SE3> last_offered_map_keyframe_;  ///< kept or revisit: the spacing of map keyframes
  double path_ = 0.0;                               ///< m of LiDAR path, registered sweeps
  std::optional<SE3> last_lidar_pose_;
  SensorStatistics lidar_statistics_;
  // Cameras: the visual odometry, its images' counts per sensor, and where its world lies in
  // the Frontend's (T_frontend_visual, set at its first tracked frame).
  std::unique_ptr<CameraOdometry> camera_odometry_;
  std::map<std::string, SensorStatistics, std::less<>> camera_statistics_;
  // A detector's output per camera (push_detections): recent messages not yet matched, and
  // the image waiting for its own (fusion.vision.dynamic_objects.wait_for_detections).
  struct CameraDetections {
    std::deque<msgs::DetectionsMessage> recent;
    std::optional<msgs::ImageMessage> waiting;
    std::optional<Timestamp> last_image_time;  // the newest image tracked
    bool streaming = false;                    // its detector has answered
    bool external = false;                     // a vision pipeline's output came (pushed)
  };
  std::map<std::string, CameraDetections, std::less<>> camera_detections_;
  /// fusion.vision.detector (none when its type is none), and its time spent (ms).
  std::unique_ptr<CameraDetector> detector_;
  double detector_ms_sum_ = 0.0;
  /// Segmentations and moving objects onto the 3D LiDAR's points (none without both).
  std::unique_ptr<SemanticProjection> semantic_projection_;
  /// Leaves a sweep's points on moving objects out before its registration (and the map).
  void mask_moving_points(LidarInertialOdometry::PreparedScan& prepared);
  /// The registered sweep's points without those on moving objects, with their segmentation
  /// classes (empty when no camera's output labelled any).
  std::pair<std::vector<Eigen::Vector3f>, std::vector<uint16_t>> label_sweep(Timestamp time, const std::vector<Eigen::Vector3f>& points);
  double masked_share_sum_ = 0.0;
  std::optional<SE3> visual_world_;
  SE3 visual_world_correction_;  ///< the Frontend's world correction visual_world_ follows
  /// Frames the odometry reported initializing (their cameras): one of them may become the
  /// monocular map's origin, posed when the map is made.
  std::vector<std::pair<Timestamp, std::vector<std::string>>> initializing_frames_;
  /// The newest left images of rig 0 (8-bit grey, copied), body clock: camera relocalization.
  std::deque<std::pair<Timestamp, cv::Mat>> recent_camera_images_;
  std::vector<std::unique_ptr<VisualLoopClosures>> visual_loops_;  ///< per camera rig: frontend.type msckf with loop_closure
  std::unique_ptr<SessionSplats> splats_;             ///< fusion.mapping.splats
  /// Images of the splats' camera waiting for the Frontend's pose become views.
  void take_splat_views();
  MappingSummary summary_;
  /// keep_trajectory: emitted poses and keyframes, both as the filter had them before any
  /// correction (Frontend::world_correction() undone), for optimized_trajectory().
  std::vector<StampedPose> uncorrected_poses_;
  struct KeyframeRecord {
    uint64_t keyframe_id = 0;
    Timestamp timestamp;
    SE3 T_world_body_uncorrected;
    SE3 world_correction;  ///< the Frontend's world correction when it was emitted
  };
  std::vector<KeyframeRecord> keyframe_records_;
  Frontend::PoseCallback pose_callback_;
  Frontend::InnovationCallback innovation_callback_;
  std::map<std::string, bool, std::less<>> last_update_applied_;  ///< per sensor: its latest update passed the gate
  std::map<std::string, bool, std::less<>> gnss_without_fix_;     ///< per GNSS sensor: its latest fix is below min_fix
  bool last_sweep_degenerate_ = false;
  bool last_sweep_weather_ = false;
  std::optional<HealthReason> camera_lost_reason_;  // the latest camera frame was lost, and why
  int registration_failures_ = 0;  ///< LiDAR sweeps in a row that did not register
  std::vector<SensorHealth> last_health_;
  std::vector<HealthChange> health_changes_;
  std::optional<Timestamp> last_health_time_;
  KeyframeCallback keyframe_callback_;
  MapUpdateCallback map_update_callback_;
  ScanCallback scan_callback_;
};

}  // namespace hanzo::fusion::pipeline
