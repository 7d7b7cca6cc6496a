#pragma once
// FusionConfig: the spec's fusion configuration file ("Filter Configuration"):
//
//   fusion:
//     frontend:
//       type: ekf            # ekf | ukf | particle             (default ekf)
//       predict_rate: 200    # Hz, IMU propagation rate          (default 200)
//       covariance: {...}    # see CovarianceConfig               (defaults below)
//     sensors:
//       imu: {topic: /sensors/imu, rate: 200, body_frame: imu_link}
//       lidar: {topic: ..., rate: 10, body_frame: lidar_link, type: velodyne_vlp16}
//
// The spec's example loads unchanged. Errors name the file, line and key path, e.g.
// "fusion.yaml:12: sensors.gnss.rate: expected a positive rate in Hz, got -5".
// Unknown keys are errors (they are usually typos). Full reference: docs/configuration.md.

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/geodesy.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::config {

/// kMsckf: the EKF, with the cameras' images through visual-inertial odometry (the MSCKF).
enum class FrontendType { kEkf, kUkf, kParticle, kMsckf };
std::string_view to_string(FrontendType type);  // "ekf", "ukf", "particle", "msckf"
std::optional<FrontendType> frontend_type_from_string(std::string_view name);

/// What kind of sensor a configured sensor is. Inferred from the sensor's name (imu*, lidar*,
/// camera*, gnss* or gps*, wheel* or odom*, radar*) unless given as `modality:`.
enum class SensorModality { kImu, kLidar, kCamera, kGnss, kWheelOdometry, kRadar, kRange };
/// SensorConfig::type of a lidar sensor that is a 2D laser scanner (planar scan matching).
inline constexpr std::string_view kPlanarLaserType = "planar_laser";
/// SensorConfig::type of a depth camera: its depth images (depth16 / depth32f) are registered to
/// the camera configured just before it (the same pixel grid), an RGB-D camera's two streams.
inline constexpr std::string_view kDepthCameraType = "depth";
std::string_view to_string(SensorModality modality);  // "imu", "lidar", "camera", "gnss", "wheel_odometry", "radar", "range"
/// The modality a message belongs to (an ImuMessage: imu, a PointCloudMessage: lidar, ...).
SensorModality modality_of(const msgs::SensorMessage& message);
std::optional<SensorModality> sensor_modality_from_string(std::string_view name);
/// The modality a sensor name implies, if any ("camera_left" -> kCamera, "wheels" -> kWheelOdometry).
std::optional<SensorModality> infer_modality(std::string_view sensor_name);

/// Initial state uncertainty and IMU noise (spec "covariance" block). All values are 1-sigma
/// standard deviations (not variances) and must be finite and >= 0.
struct CovarianceConfig {
  Eigen::Vector3d initial_position{0.1, 0.1, 0.1};       // m, per axis (world x, y, z)
  Eigen::Vector3d initial_orientation{0.01, 0.01, 0.01};  // rad, per axis (roll, pitch, yaw errors)
  Eigen::Vector3d initial_velocity{0.1, 0.1, 0.1};        // m/s, per axis
  double process_noise_accel = 0.1;       // m/s^2, accelerometer white noise
  double process_noise_gyro = 0.01;       // rad/s, gyroscope white noise
  double accel_bias_random_walk = 0.001;  // m/s^2/sqrt(Hz)
  double gyro_bias_random_walk = 0.0001;  // rad/s/sqrt(Hz)
};

/// frontend.ukf: sigma-point scaling (Wan & van der Merwe 2000).
struct UkfSettings {
  double alpha = 0.001;  // (0, 1]
  double beta = 2.0;     // >= 0
  double kappa = 0.0;    // 18 + kappa > 0
};

/// frontend.motion_model: how the state moves between measurements when the configuration has
/// no IMU (LiDAR only, LiDAR + wheels, wheels + GNSS). Constant velocity and constant angular
/// velocity, both driven by white noise: the velocity random walk acceleration_noise and the
/// angular-velocity random walk angular_acceleration_noise (continuous-time densities).
struct MotionModelSettings {
  double acceleration_noise = 2.0;          // m/s^2/sqrt(Hz), > 0: how fast the speed may change
  double angular_acceleration_noise = 1.0;  // rad/s^2/sqrt(Hz), > 0: how fast the turn rate may change
};

/// frontend.particle_filter.
struct ParticleFilterSettings {
  int particles = 1000;             // 100 .. 100000
  double resample_threshold = 0.5;  // resample when the effective sample size < this * particles, (0, 1]
  uint64_t seed = 1;                // random numbers: the same seed and input give the same output
};

/// s: the keyframe interval of frontend.type msckf when none is given. Features tracked from one
/// keyframe to the next become the visual-inertial graph's landmarks; measured on six simulated
/// flights and walks, 0.5 s gave a graph 1.1-3.2x more accurate than 1 s (bench/RESULTS.md).
inline constexpr double kVisualInertialKeyframeInterval = 0.5;
/// s: the keyframe interval of the other frontends when none is given (the spec's 1 Hz).
inline constexpr double kDefaultKeyframeInterval = 1.0;

/// hanzo-fusion's additions to the spec's frontend block (how the Frontend fuses; all optional).
struct FrontendConfig {
  FrontendType type = FrontendType::kEkf;
  double predict_rate_hz = 200.0;  // > 0
  CovarianceConfig covariance;
  /// Chi-square gate probability of every update, in (0, 1]; 1 turns gating off.
  double gate_probability = 0.999;
  /// s >= 0: a sensor gated continuously for this long is fused without the gate once (the
  /// estimate is then the likelier culprit); 0 never. Longer than the sensor faults it should
  /// ride out (wheel slip, multipath episodes).
  double gate_recovery_s = 10.0;
  /// s >= 0: a message older than the newest fused one by at most this is fused by rolling
  /// back and re-propagating; older ones are rejected as too late. 0 rejects every late message.
  double lag_window_s = 0.5;
  /// s > 0: a message this far ahead of the newest accepted time is rejected as future-dated
  /// unless the next message confirms the jump (a pause of the whole robot).
  double max_future_s = 1.0;
  /// s > 0: IMU data averaged for static alignment (gravity direction, gyro bias) at start.
  double static_alignment_s = 1.0;
  /// Ground robot on a flat floor: height and vertical speed held (robot_localization's two_d_mode).
  bool planar = false;
  /// Zero-velocity updates when the wheels stand still.
  bool zero_velocity_updates = true;
  /// s > 0: a Keyframe (pose + relative motion and covariance since the previous one) for the
  /// backend every this many seconds. Absent: kDefaultKeyframeInterval (the spec's 1 Hz), or
  /// kVisualInertialKeyframeInterval for type msckf (keyframe_interval() says which applies).
  std::optional<double> keyframe_interval_s;
  double keyframe_interval() const {
    return keyframe_interval_s.value_or(type == FrontendType::kMsckf ? kVisualInertialKeyframeInterval : kDefaultKeyframeInterval);
  }
  /// WGS84 origin of the world ENU frame; when absent the first GNSS fix becomes the datum.
  std::optional<GeodeticPoint> datum;
  /// rad, ENU (0 = east, counter-clockwise): the start heading when it is known (a robot that
  /// always starts docked the same way). Absent: with GNSS the heading comes from the GNSS
  /// track (poses are INITIALIZING until then); without GNSS the start heading is 0 (the world
  /// frame is the start pose).
  std::optional<double> initial_yaw;
  UkfSettings ukf;
  ParticleFilterSettings particle_filter;
  MotionModelSettings motion_model;
};

/// How a sensor's messages are fused (keys under the sensor; each applies to one modality).
struct SensorFusionOptions {
  /// s >= 0: silence longer than this reports the sensor as timed out; 0 means 5 periods
  /// (5 / rate), at least 0.1 s.
  double timeout_s = 0.0;
  // imu
  std::array<bool, 3> use_orientation{false, false, false};  // roll, pitch, yaw of the message's orientation
  double orientation_noise = 0.01;  // rad, when the message has no orientation covariance
  // wheel_odometry
  double speed_noise = 0.05;          // m/s, forward speed
  double yaw_rate_noise = 0.05;       // rad/s
  double lateral_speed_noise = 0.05;  // m/s, non-holonomic constraint
  bool use_yaw_rate = false;  // the gyro measures it better; wheel scale errors bias it
  bool non_holonomic = true;
  // gnss
  msgs::GnssFixType min_fix = msgs::GnssFixType::kFix3d;  // weaker fixes are rejected
  // radar
  double velocity_noise = 0.1;  // m/s, ego-velocity per axis
};

/// A keypoint detector and descriptor of the visual frontends: ORB (classical, the default) or a
/// learned model (the AI module, HANZO_FUSION_AI: docs/learned-features.md).
struct FeatureSelection {
  std::string type = "orb";  // one of feature_type_names()
  std::string model;         // learned: the weights (.pth); empty: <type>.pth in $HANZO_FUSION_MODELS
  bool learned() const { return type != "orb"; }
  bool operator==(const FeatureSelection& other) const { return type == other.type && model == other.model; }
};
/// "orb", then the learned models: "aliked-t16", "aliked-n16", "aliked-n16rot", "aliked-n32",
/// "alike-t", "alike-s", "alike-n", "alike-l".
const std::vector<std::string_view>& feature_type_names();
/// A known type; a model path only for a learned one. `field` names the key in the error.
Status validate(const FeatureSelection& features, const std::string& field);

/// How the visual odometry matches two views before RANSAC: kRatio, the ratio test; kLearned,
/// the learned correspondence filter (vision/correspondence_filter.hpp) on mutual matches.
enum class MatcherType { kRatio, kLearned };
std::string_view to_string(MatcherType type);  // "ratio", "learned"

/// Where the visual odometry's loop-closure candidates come from: kBow, bags of ORB words;
/// kLearned, VLAD vectors of learned descriptors (vision/vlad.hpp).
enum class PlaceRecognitionType { kBow, kLearned };
std::string_view to_string(PlaceRecognitionType type);  // "bow", "learned"

/// A camera's detector output (msgs::DetectionsMessage) in a sensor log: on the camera's topic
/// with this suffix ("/sensors/camera/detections").
inline constexpr std::string_view kDetectionsTopicSuffix = "/detections";

/// fusion.vision.dynamic_objects: a detector's boxes (msgs::DetectionsMessage, pushed on a
/// camera's sensor name) mask moving objects out of that camera's visual odometry
/// (pipeline/dynamic_mask.hpp).
struct DynamicObjectsConfig {
  /// Classes that move (matched without regard to case); boxes of other classes stay usable.
  std::vector<std::string> classes = {"person", "pedestrian", "people", "rider", "cyclist", "bicycle", "motorcycle", "car",
                                      "vehicle", "truck", "bus", "train", "forklift", "animal", "dog", "cat", "horse"};
  double min_score = 0.3;  // [0, 1]: weaker detections are not masked
  double margin_px = 8.0;  // >= 0: each box grown by this on every side, each instance mask dilated by it
  /// An image of a camera whose detections have come waits for its own detections: until they
  /// come or the next image of any camera does (a detector's latency up to one frame costs
  /// nothing; one that never answers delays each image by one frame). false: images never
  /// wait, detections that come after their image are counted late.
  bool wait_for_detections = true;

  bool operator==(const DynamicObjectsConfig&) const = default;
};

/// fusion.vision.detector: an object detector the Session runs on each camera image that comes
/// without a vision pipeline's detections (a camera whose detections are pushed keeps those);
/// its boxes are used as pushed ones are (dynamic_objects masks, classes on the 3D LiDAR's points).
/// type "nanodet": the AI module's NanoDet (ai/object_detector.hpp, docs/semantics.md), 80 COCO
/// classes ("person", "car", "truck", ...); "none" (default): only pushed detections.
struct DetectorSelection {
  std::string type = "none";     // "none" or "nanodet"
  std::string model;             // nanodet: the model's JSON; empty: nanodet.json in $HANZO_FUSION_MODELS
  double score_threshold = 0.35; // (0, 1): weaker boxes are not reported
  bool enabled() const { return type != "none"; }
  bool operator==(const DetectorSelection&) const = default;
};

/// fusion.vision: the visual frontends' features, matching and place recognition; a camera
/// sensor's `features` key overrides `features` for that camera.
struct VisionConfig {
  FeatureSelection features;
  MatcherType matcher = MatcherType::kRatio;
  /// Unset: bow with ORB features, learned with learned ones (each the only kind that fits).
  std::optional<PlaceRecognitionType> place_recognition;
  std::string place_model;  // learned: the VLAD model file; empty: vlad_<features>.hzvlad of the trained models
  /// The visual odometry's local mapping on its own thread (vision::VisualOdometryConfig):
  /// lower latency per image; false (default): keyframe poses fused after their bundle adjustment.
  bool local_mapping_thread = false;
  DynamicObjectsConfig dynamic_objects;
  DetectorSelection detector;
};

/// A live sensor's driver (`hanzo-fusion drive`, docs/drivers.md): the decoder of its bytes and
/// where they come from. Paths as given (relative to the working directory).
struct SensorDriverConfig {
  std::string type;         // velodyne, ouster, hesai (lidar); nmea (gnss); xsens (imu)
  std::string source;       // udp://[address]:port, tcp://host:port, serial:///dev/NAME?baud=N
  std::string model;        // velodyne: VLP-16, VLP-32C, HDL-32E, HDL-64E, VLS-128
  std::string calibration;  // velodyne: db.xml or ROS YAML (optional); hesai: angle correction CSV (required)
  std::string firetime;     // hesai: firetime correction CSV (optional)
  std::string metadata;     // ouster: the sensor's metadata JSON (required)
};

/// The driver types and the modality each one delivers.
const std::vector<std::pair<std::string_view, SensorModality>>& sensor_driver_types();

struct SensorConfig {
  std::string name;  // the key under `sensors:`, also the calibration's "<name>_to_body"
  SensorModality modality = SensorModality::kImu;
  std::string topic;       // default "/sensors/<name>"
  double rate_hz = 0.0;    // required, > 0: nominal rate, used for timeouts and summaries
  std::string body_frame;  // default "<name>_link"
  std::string type;        // optional model, e.g. "velodyne_vlp16", "stereo_left"; "" when not given;
                           // kPlanarLaserType marks a 2D laser scanner (its scans are planar),
                           // kDepthCameraType a camera's registered depth images
  SensorFusionOptions fusion;
  std::optional<FeatureSelection> features = std::nullopt;  // cameras: this camera's features (else fusion.vision.features)
  std::optional<SensorDriverConfig> driver = std::nullopt;  // live input (`drive`); none: fed by logs, gRPC, REST

  /// The timeout in seconds (the default applied).
  double effective_timeout_s() const;
};

/// fusion.mapping: the Frontend's LiDAR odometry, keyframe graph, loop closure and map. The
/// LiDAR settings apply when a 3D LiDAR is configured; the graph runs with any sensors.
/// 3D Gaussian splats trained while a session runs, from its camera's images at the session's
/// poses (pipeline/session_splats.hpp; builds with the AI module, HANZO_FUSION_AI).
struct SplatMappingConfig {
  bool enabled = false;         // off: the training takes CPU a small computer's odometry may need
  int image_width = 160;        // px >= 16: views downscaled by the integer factor nearest this width
  int steps_per_view = 10;      // >= 1, replay: optimizer steps after each new view (deterministic)
  double cpu_share = 0.5;       // (0, 1], realtime: share of one core the background training takes
  int max_gaussians = 200000;   // >= 1000
};

struct MappingConfig {
  bool enabled = true;                 // false: the filter alone (no LiDAR odometry, graph or map)
  double lidar_voxel = 1.0;            // m > 0: LiDAR odometry local-map voxel and neighbour radius
  double lidar_source_voxel = 1.0;     // m > 0: registration points downsampled to this (0.25 indoors)
  double lidar_max_range = 100.0;      // m > 0: farther returns ignored
  double map_voxel = 0.2;              // m > 0: point map layer
  double occupancy_resolution = 0.1;   // m > 0: 2D occupancy layer
  double keyframe_distance = 1.0;      // m >= 0 of LiDAR motion between map keyframes
  double keyframe_angle = 0.2;         // rad >= 0 of LiDAR rotation between map keyframes
  bool remove_moving_points = true;    // points the later (or earlier) scans saw through leave the point map (maps/point_map.hpp)
  bool loop_closure = true;            // Scan Context candidates verified by registration
  double loop_min_travel = 50.0;       // m > 0 of path between the two ends of a loop
  double loop_search_radius = 10.0;    // m > 0: candidates within this (+5 % of the path between) of the estimate
  double loop_max_rmse = 0.1;          // m > 0: registration inlier RMSE a loop must reach
  bool gnss_factors = true;            // fused GNSS fixes become GPS factors of the graph
  bool velocity_factors = true;        // fused radar and wheel velocities become velocity factors of the graph
  double gnss_error_correlation = 10.0;  // s >= 0: time constant of the GNSS error in the graph (0: fixes independent)
  bool follow_graph = true;            // the LiDAR-inertial graph holds the GNSS fixes; the frontend follows it every update
  int visual_inertial_window = 40;     // keyframes >= 0 of the visual-inertial graph's sliding window (0: keep every keyframe)
  SplatMappingConfig splats;
};

struct FusionConfig {
  FrontendConfig frontend;
  MappingConfig mapping;
  VisionConfig vision;
  std::vector<SensorConfig> sensors;  // in file order

  const SensorConfig* find_sensor(std::string_view name) const;
  /// The features a camera uses: its own `features`, else vision.features.
  const FeatureSelection& features_of(const SensorConfig& camera) const { return camera.features ? *camera.features : vision.features; }
};

/// Checks a configuration built in code with the same rules the loader applies: positive
/// rates, finite non-negative noise values, unique non-empty sensor names and topics.
Status validate(const FusionConfig& config);

Result<FusionConfig> load_fusion_config(const std::string& path);
/// source_name stands in for the file name in error messages.
Result<FusionConfig> parse_fusion_config(const std::string& yaml_text, const std::string& source_name);
/// The spec's layout; parse_fusion_config(to_yaml(c)) reproduces c exactly.
std::string to_yaml(const FusionConfig& config);
/// Writes to_yaml(config) to path (atomically: a temporary file renamed into place).
Status save_fusion_config(const FusionConfig& config, const std::string& path);

}  // namespace hanzo::fusion::config
