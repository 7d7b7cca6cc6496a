#pragma once
// pipeline::Frontend: one agent's real-time filter (spec, "Fusion Pipeline Architecture"), the
// first stage of pipeline::Session (session.hpp), which adds the LiDAR odometry, the graph and
// the map. Messages from any sensor go in with push(); pose estimates come out at the IMU rate.
//
//   auto frontend = Frontend::create(fusion_config, calibration).value();
//   frontend->set_pose_callback([](const msgs::PoseEstimate& pose) { ... });
//   for (...) { if (PushStatus s = frontend->push("gnss", message); !s) log(to_string(s.reason()), s.error().message); }
//
// What push() does with a message (docs/frontend.md has the full story):
//  1. Input checks, each a Rejection (rejection.hpp) that push() returns and summary() counts:
//     unknown_sensor, wrong_type (a GNSS message for an IMU sensor), invalid (msgs::validate:
//     NaN, bad covariance...), duplicate (same timestamp as the sensor's previous message),
//     out_of_order (older than the sensor's previous message), future_dated (more than
//     frontend.max_future ahead of the newest accepted time, unless the next message confirms
//     the jump), too_late (older than the newest fused time by more than frontend.lag_window).
//     The sensor's calibrated time offset is applied first (t_body = t_sensor + offset).
//  2. Time ordering: measurements wait until the IMU has reached their time, then are fused in
//     timestamp order. A message that arrives after the filter has passed its time (inside the
//     lag window) is fused by restoring the stored estimate from before it and re-fusing what
//     followed (no silent drop; counted as rolled_back).
//  3. Fusion, each update chi-square gated (counted per sensor: fused, gated, ...).
//     IMU: static alignment at start (roll, pitch, gyro bias), then propagation; spikes
//     rejected; optional attitude (use_orientation). GNSS: fix-type policy, WGS84 -> ENU via
//     the datum, lever arm. Wheels: forward speed (+ non-holonomic constraint, + yaw rate),
//     zero-velocity update when the wheels stand still. Poses (LiDAR / visual localization):
//     push_pose().
//  4. Monitoring: a sensor silent for longer than its timeout is reported (counted, logged) and
//     the filter keeps running on the rest. PoseEstimate.status counts the modalities that
//     constrained the estimate within their timeouts (the IMU counts while it streams); the
//     spec requires two for reliable localization: state TRACKING with >= 2, DEGRADED with
//     fewer or with a sensor timed out, LOST without IMU data (without an IMU: when no
//     modality constrained the estimate within its timeout), INITIALIZING before alignment.
//
// Without an IMU sensor (LiDAR only, LiDAR + wheels, wheels + GNSS) a constant-velocity
// motion model propagates instead (frontend.motion_model); without a LiDAR or camera either,
// the wheels' yaw rate is the turn's only measurement (fused whatever use_yaw_rate says); poses
// come with each fused measurement.
//
// Deterministic: the same messages in the same order give bit-identical output. Not
// thread-safe: one thread pushes (the server serializes per session).

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/pipeline/rejection.hpp"

namespace hanzo::fusion::pipeline {

/// Counters of one configured sensor.
struct SensorStatistics {
  std::string name;
  config::SensorModality modality = config::SensorModality::kImu;
  uint64_t received = 0;  // push() calls for this sensor
  uint64_t fused = 0;     // messages whose update moved the estimate (IMU: propagated)
  uint64_t rolled_back = 0;  // late messages fused by rolling back
  /// Rejections by reason (rejection.hpp): the input checks above plus the fusion outcomes
  /// (gated, no_fix, spike, ...; not_fused: a modality the frontend does not fuse directly,
  /// e.g. raw LiDAR scans without odometry).
  std::map<Rejection, uint64_t> rejected;
  uint64_t timeouts = 0;     // times the sensor went silent for longer than its timeout
  bool timed_out = false;    // silent now
  Timestamp first_time;      // first and last accepted timestamps (body clock)
  Timestamp last_time;
  double nis_sum = 0.0;      // sum of normalized innovations squared of fused updates
  uint64_t nis_count = 0;    // and their degrees of freedom (for the average NIS per dof)

  uint64_t rejected_total() const;
};

struct SessionSummary {
  std::vector<SensorStatistics> sensors;  // in configuration order
  uint64_t poses = 0;                     // PoseEstimates emitted
  uint64_t keyframes = 0;
  uint64_t corrections = 0;               // backend corrections applied
  uint64_t rollbacks = 0;                 // times the filter rolled back for a late message
  uint64_t zero_velocity_updates = 0;
  std::string filter;                     // "ekf", ...
  /// The tracking state now (the rules of PoseEstimate.status with the sensors' current
  /// timeouts), which a later message can change without a new pose.
  msgs::TrackingState state = msgs::TrackingState::kInitializing;
  /// With wheel odometry, once initialized: the estimated wheel speed scale (1.02: the wheels
  /// read 2 % more distance than driven; their radius is 2 % too large) and its 1-sigma.
  std::optional<double> wheel_speed_scale;
  double wheel_speed_scale_sigma = 0.0;
  /// With an IMU and the wheels' yaw rate fused (use_yaw_rate), once initialized: the estimated
  /// gyro yaw-rate scale (1.01: the gyro reads turns about the body's z axis 1 % high) and its 1-sigma.
  std::optional<double> gyro_yaw_scale;
  double gyro_yaw_scale_sigma = 0.0;
  /// With an IMU and the wheels' yaw rate fused: the turn the wheels report per metre driven
  /// straight (rad/m; (s_right - s_left) / wheel separation for unequal wheel scales) and its 1-sigma.
  std::optional<double> wheel_heading_drift;
  double wheel_heading_drift_sigma = 0.0;
};

/// One update, for diagnostics (innovation plots, consistency checks).
struct InnovationRecord {
  std::string sensor;
  std::string_view model;  // "gnss_position", "wheel_odometry", ...
  Timestamp timestamp;
  std::vector<double> innovation;  // z (-) h(x) before the update
  double mahalanobis_squared = 0.0;
  bool applied = false;
};

/// A GNSS fix the filter fused (past the fix-type policy and the chi-square gate), in the
/// world frame: for the backend's GPS factors.
struct FusedGnssFix {
  std::string sensor;
  Timestamp timestamp;                  ///< body clock
  Eigen::Vector3d antenna_world;        ///< ENU of the session's datum, m
  Eigen::Matrix3d covariance;           ///< m^2, ENU
  Eigen::Vector3d lever_arm;            ///< the antenna in the body frame (calibration), m
  /// The fused pose at the fix, in the world as the session had it then (corrections applied
  /// later move it by world_correction(): relate it to other poses through their corrections).
  SE3 T_world_body;
  SE3 world_correction;                 ///< Frontend::world_correction() of that world
};

/// A sensor velocity the Frontend fused (a radar's ego velocity, wheel odometry's speed with
/// the non-holonomic zeros, a wheel standstill), for the keyframe graph's velocity factors.
struct FusedVelocity {
  std::string sensor;
  Timestamp timestamp;                 ///< body clock
  Eigen::Vector3d velocity_sensor;     ///< m/s, sensor axes (wheel speeds divided by the estimated wheel scale)
  Eigen::Matrix3d covariance;          ///< (m/s)^2, sensor axes
  SE3 T_body_sensor;
  Eigen::Vector3d angular_rate_body;   ///< rad/s, the gyro with its estimated bias removed
};

class Frontend {
 public:
  using PoseCallback = std::function<void(const msgs::PoseEstimate&)>;
  using InnovationCallback = std::function<void(const InnovationRecord&)>;
  using KeyframeCallback = std::function<void(const msgs::Keyframe&)>;
  using GnssCallback = std::function<void(const FusedGnssFix&)>;
  using VelocityCallback = std::function<void(const FusedVelocity&)>;

  /// Fails when the configuration or the calibration is invalid. Without an IMU sensor the
  /// state moves by a constant-velocity motion model between measurements
  /// (frontend.motion_model): the filter starts level at the first message, and poses come
  /// with every fused measurement instead of every IMU message.
  static Result<std::unique_ptr<Frontend>> create(const config::FusionConfig& config, const calib::Calibration& calibration);
  ~Frontend();
  Frontend(const Frontend&) = delete;
  Frontend& operator=(const Frontend&) = delete;

  /// Fuses one message of the named sensor (the configuration's name). When the input checks
  /// refuse it, the PushStatus carries the Rejection (error().message "too_late: ...") and the
  /// session is unchanged. Fusion outcomes (gated...) are counted, not returned.
  PushStatus push(std::string_view sensor, const msgs::SensorMessage& message);
  /// A pose measurement T_world_sensor of a lidar or camera sensor (LiDAR / visual
  /// localization), covariance over (position world [m], rotation sensor frame [rad]).
  /// gated = false fuses it without the chi-square gate: for poses whose source already
  /// rejected its outliers and whose corrections the filter must follow (a visual-inertial
  /// filter's poses: it integrates the same IMU with the images' help and is the better
  /// estimate; a phone-grade IMU between its frames is not a reason to refuse its poses).
  PushStatus push_pose(std::string_view sensor, Timestamp timestamp, const SE3& T_world_sensor,
                   const Eigen::Matrix<double, 6, 6>& covariance, bool gated = true);

  /// A pose of a lidar or camera sensor in its own map frame (an odometry's local map), covariance
  /// over (position in the map's axes [m], rotation sensor frame [rad]). The sensor's first map
  /// pose defines the frame where the estimate puts the sensor then; from there the map frame's
  /// pose in the world is estimated with the state (estimate/map_frame.hpp: its roll and pitch
  /// against gravity once turns separate them from the accelerometer bias, its position and
  /// heading against GNSS), so that a map started from a tilted alignment or a poor first fix
  /// does not hold the estimate there. With a filter that does not estimate map frames (ukf,
  /// particle) the frame stays fixed where it was defined, moved by world corrections. A
  /// filter reset (a heading alignment) defines the frame again at the next map pose.
  PushStatus push_map_pose(std::string_view sensor, Timestamp timestamp, const SE3& T_map_sensor,
                           const Eigen::Matrix<double, 6, 6>& covariance);
  /// The current estimate of `sensor`'s map frame in the world (push_map_pose), in today's
  /// world; none before the sensor's first map pose was fused or for an unknown sensor.
  std::optional<SE3> map_frame(std::string_view sensor) const;

  /// Fuses every message still waiting for the IMU to reach its time (call at the end of a
  /// log or when the IMU stops for good); the filter is extrapolated with the last IMU sample.
  void flush();

  /// Whether an IMU propagates the state (else the motion model does).
  bool has_imu() const;
  /// Without an IMU: moves the estimate to `time` (body clock) by the motion model, starting
  /// the filter there when it has not started, so that pose_at() covers `time` (the Session
  /// does this before it registers a LiDAR sweep). Waiting messages are fused first. No pose
  /// is emitted. Does nothing with an IMU (its messages drive time) or for a time at or
  /// before the newest fused event.
  void propagate_to(Timestamp time);

  /// A relative-pose measurement of a lidar or camera sensor (LiDAR / visual odometry between
  /// two scans or frames): T_from_to maps the sensor frame at `to` into the sensor frame at
  /// `from`; covariance over its tangent (rho, phi), right perturbation. Fused at `to` as the
  /// sensor's mean velocity over the interval, R^T t / (to - from) in the `to` frame
  /// (robot_localization's differential mode); fails for to <= from.
  PushStatus push_relative_pose(std::string_view sensor, Timestamp from, Timestamp to, const SE3& T_from_to,
                            const Eigen::Matrix<double, 6, 6>& covariance);

  /// Marks that `sensor`'s data arrived at `time` (sensor clock) although it reaches the filter
  /// only later or through another sensor's measurements (images before the visual odometry's
  /// first pose, the right camera of a stereo pair): its timeout monitoring counts it as heard;
  /// the ordering checks of its own measurements are not affected. Ignores unknown sensors.
  void note_input(std::string_view sensor, Timestamp time);

  /// Extra silence (s of data time, >= 0; default 0) tolerated before a sensor counts as timed
  /// out. A live session's sensors reach it through separate streams that may run up to the lag
  /// window apart (a client replaying a log at full speed, one stream per sensor): without it the
  /// stream that lags is reported silent while it is only behind.
  void set_timeout_grace(double seconds);
  /// Starts the filter at `state` (a PoseEstimate of this session's filter, such as the newest
  /// stored pose of a session a replica takes over from a failed one) at the first IMU sample,
  /// without a static alignment; the estimates are in that state's world frame. Position and
  /// world-frame velocity are carried to the sample's time at constant velocity; the IMU biases
  /// start at zero with their initial uncertainty. Takes effect only before the first message;
  /// without an IMU the filter starts with its static alignment.
  void resume(const msgs::PoseEstimate& state);

  /// The configured sensor that reads `topic`, or nullptr. A camera's detector output
  /// (msgs::DetectionsMessage) comes on its topic + config::kDetectionsTopicSuffix.
  const config::SensorConfig* sensor_for_topic(std::string_view topic) const;
  const config::FusionConfig& config() const;

  /// Called for every PoseEstimate (one per IMU message once initialized), in time order.
  void set_pose_callback(PoseCallback callback);
  void set_innovation_callback(InnovationCallback callback);
  /// Called for every Keyframe (frontend.keyframe_interval apart): the pose, its covariance, and
  /// the relative motion since the previous keyframe with its covariance (from the filter's pose
  /// clone, cross-correlations included). A keyframe is sent once it is final: when the filter
  /// has passed it by more than frontend.lag_window (no late message can re-make it), or at
  /// flush(); its pose is in the world of the moment it is sent.
  void set_keyframe_callback(KeyframeCallback callback);
  /// Called once for every GNSS fix the filter fused (a fix re-fused by a rollback is not
  /// reported again), after the pose it corrected.
  void set_gnss_callback(GnssCallback callback);
  /// Called with every radar or wheel velocity fused (in fusion order, from push()).
  void set_velocity_callback(VelocityCallback callback);
  /// For a backend that fuses GNSS positions itself and moves this Frontend onto its estimate
  /// (apply_correction after each of its updates): once the heading is known, fixes past the
  /// fix-type policy and the chi-square gate go to the GNSS callback without updating the
  /// filter, so that the backend's graph holds each fix once. Until the heading is known (the
  /// GNSS track aligns it) the filter fuses them as usual. Off again: the filter fuses them.
  /// A fix passed on counts as fused in the sensor's statistics and health, and its innovation
  /// record says applied (it passed the gate and the backend takes it).
  void set_gnss_positions_to_backend(bool enabled);

  /// The backend's hook: keyframe `keyframe_id` is really at T_world_body_optimized. The
  /// estimate is moved rigidly by T_optimized * T_keyframe^-1 (world frame), now. Fails for a
  /// keyframe this Frontend never emitted or no longer remembers (it keeps the last 100000).
  /// Corrections compose: the keyframe's pose is taken as the Frontend believes it now (the
  /// emitted pose moved by the corrections applied since), so correcting the same keyframe
  /// twice to the same pose moves the estimate once.
  Status apply_correction(uint64_t keyframe_id, const SE3& T_world_body_optimized);
  /// The product of the corrections fused so far (world frame, newest on the left): a pose
  /// that was T_world_body before them is world_correction() * T_world_body now.
  SE3 world_correction() const;
  /// The IMU's bias estimates now (accelerometer m/s^2, gyroscope rad/s, in the IMU's axes);
  /// none before initialization or without an IMU.
  std::optional<std::pair<Eigen::Vector3d, Eigen::Vector3d>> imu_bias() const;
  /// The latest PoseEstimate, if any.
  std::optional<msgs::PoseEstimate> latest_pose() const;
  /// T_world_body at a past time within the lag window (body clock), interpolated between the
  /// fused estimates around it, in today's world (corrections applied since included): the
  /// prediction an odometry module (LiDAR, visual) starts from.
  /// None before initialization, for times older than the kept history or newer than the
  /// last fused event.
  std::optional<SE3> pose_at(Timestamp time) const;
  SessionSummary summary() const;

 private:
  struct Impl;
  explicit Frontend(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace hanzo::fusion::pipeline
