#pragma once
// Estimator: the part of a Frontend that turns time-ordered events into filter operations. It
// holds everything fusion depends on (filter, last IMU sample, previous wheel reading, datum,
// alignment buffer), and is copyable, so the Frontend can snapshot it after each event and roll
// back for a late message. Private to the pipeline module.

#include <functional>
#include <memory>
#include <optional>
#include <string_view>
#include <variant>
#include <vector>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/geodesy.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/estimate/filter.hpp"
#include "hanzo/fusion/estimate/imu_spike_filter.hpp"
#include "hanzo/fusion/estimate/in_motion_alignment.hpp"
#include "hanzo/fusion/estimate/velocity_models.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/pipeline/frontend.hpp"
#include "hanzo/fusion/pipeline/rejection.hpp"

namespace hanzo::fusion::pipeline {

struct PoseMeasurement {
  SE3 T_world_sensor;  ///< with in_map: T_map_sensor, in the sensor's own map frame
  Eigen::Matrix<double, 6, 6> covariance;
  bool gated = true;  // false: fused without the chi-square gate (Frontend::push_pose)
  bool in_map = false;  // Frontend::push_map_pose
};

/// A sensor's own velocity in its axes (from a relative pose of LiDAR / visual odometry).
struct VelocityMeasurement {
  Eigen::Vector3d velocity_sensor;
  Eigen::Matrix3d covariance;
};

/// A correction from the backend: move the estimate by T_correction (world frame).
struct WorldCorrection {
  SE3 T_correction;
};

/// Without an IMU: carry the motion model forward to the event's time (Frontend::propagate_to).
struct MotionTick {};

/// A message ready for fusion: its sensor (index into FusionConfig::sensors), its body-clock
/// time and an arrival sequence number (ties at equal times keep arrival order).
struct Event {
  Timestamp time;
  size_t sensor = 0;
  uint64_t sequence = 0;
  bool is_imu = false;
  std::variant<msgs::SensorMessage, PoseMeasurement, VelocityMeasurement, WorldCorrection, MotionTick> payload;
};

/// Strict order of fusion: time, then IMU before other sensors, then arrival.
bool fused_before(const Event& a, const Event& b);

/// What the Frontend needs to know about a sensor, fixed for the session's life.
struct SensorSetup {
  const config::SensorConfig* config = nullptr;
  SE3 T_body_sensor;
  Duration time_offset;
};

/// One measurement update's outcome, reported to the Frontend's observer.
struct UpdateReport {
  size_t sensor = 0;
  std::string_view model;
  Timestamp time;
  estimate::UpdateOutcome outcome;
};

class UpdateObserver {
 public:
  virtual ~UpdateObserver() = default;
  virtual void on_update(const UpdateReport& report) = 0;
};

/// The result of fusing one event: fused, or why not (gated, spike, ...).
struct EventOutcome {
  EventOutcome() = default;
  EventOutcome(bool was_fused, std::optional<Rejection> why) : fused(was_fused), reason(why) {}
  bool fused = false;
  std::optional<Rejection> reason;
  bool zero_velocity_update = false;
  std::optional<msgs::Keyframe> keyframe;  // emitted after this IMU event
  std::optional<FusedGnssFix> gnss_fix;    // a fused GNSS event's fix (sensor name left empty)
  std::optional<FusedVelocity> velocity;   // a fused radar or wheel event's velocity (sensor name left empty)
};

/// With an IMU sensor the IMU propagates the state (strapdown) and its messages are the clock.
/// Without one (imu_sensor empty) the state moves by a motion model between measurements:
/// constant velocity in the body's axes and constant angular velocity, driven by white noise
/// (frontend.motion_model). It is the same 18-dimensional filter fed a virtual IMU whose
/// accelerometer reads the gravity reaction plus the centripetal acceleration of the turn
/// (R^T (-g) + w x v_body + accel bias) and whose gyro reads zero, so that the gyro-bias state is minus the angular velocity and its
/// random walk (angular_acceleration_noise) lets the turn rate change; the accelerometer noise
/// (acceleration_noise) lets the velocity change. The filter starts level at the first event
/// (at the GNSS fix with a datum), and every fused measurement may emit a keyframe.
class Estimator {
 public:
  Estimator(const config::FusionConfig& config, std::vector<SensorSetup> sensors, std::optional<size_t> imu_sensor);
  Estimator(const Estimator& other);
  Estimator& operator=(const Estimator& other);
  Estimator(Estimator&&) noexcept = default;
  Estimator& operator=(Estimator&&) noexcept = default;
  ~Estimator();

  /// Fuses one event; its time must not be before time(). observer may be null.
  EventOutcome process(const Event& event, UpdateObserver* observer);

  bool initialized() const { return initialized_; }
  /// Starts the filter at `state` at the first IMU sample, without a static alignment (Frontend::resume):
  /// its attitude, and its position and world-frame velocity carried to the sample's time at
  /// constant velocity; biases start at zero with their initial uncertainty. Before
  /// initialization only (ignored after).
  void resume_from(const msgs::PoseEstimate& state) {
    if (!initialized_) resume_state_ = state;
  }
  /// False while GNSS defines the world and the heading in it is not yet known (see
  /// align_heading): poses are then not TRACKING.
  bool heading_known() const { return !heading_pending_; }
  /// Whether the state's wheel speed scale is estimated (wheel odometry with GNSS, LiDAR or a camera).
  bool estimates_wheel_scale() const { return estimate_wheel_scale_; }
  bool estimates_gyro_yaw_scale() const { return estimate_gyro_yaw_scale_; }
  bool estimates_wheel_heading_drift() const { return estimate_wheel_heading_drift_; }
  /// Time of the last fused event.
  Timestamp time() const { return time_; }
  const estimate::Filter& filter() const { return *filter_; }
  /// Time of the last fused update of each sensor (IMU: last propagation), zero when never.
  const std::vector<Timestamp>& last_fused() const { return last_fused_; }
  /// The product of the backend corrections fused so far (world frame, newest on the left):
  /// a pose estimated before them is T * that pose in today's world.
  const SE3& world_correction() const { return world_correction_; }
  /// GNSS positions for the backend alone (Frontend::set_gnss_positions_to_backend): once the
  /// heading is known, a fix past the fix-type policy and the chi-square gate (evaluated on a
  /// copy of the filter) is reported in EventOutcome::gnss_fix without updating the state.
  void set_gnss_positions_to_backend(bool enabled) { gnss_positions_to_backend_ = enabled; }
  /// The current estimate of `sensor`'s map frame in the world (Frontend::push_map_pose);
  /// none before its first map pose was fused.
  std::optional<SE3> map_frame(size_t sensor) const;

 private:
  EventOutcome process_imu(const Event& event, const msgs::ImuMessage& imu, UpdateObserver* observer);
  EventOutcome process_gnss(const Event& event, const msgs::GnssMessage& gnss, UpdateObserver* observer);
  EventOutcome process_wheels(const Event& event, const msgs::WheelOdometryMessage& wheels, UpdateObserver* observer);
  /// Returns true once the heading is known: by in-motion alignment when the start was moving
  /// or the estimate's speed contradicts the GNSS track's, else by align_heading_to_course.
  bool align_heading(Timestamp time, const Eigen::Vector3d& antenna_gnss, const Eigen::Vector3d& lever, double horizontal_sigma);
  /// Static start: the dead-reckoned track against the GNSS track over the same stretch.
  bool align_heading_to_course(const Eigen::Vector3d& antenna_gnss, const Eigen::Vector3d& antenna_estimate, double horizontal_sigma);
  /// Sets the estimate to an in-motion alignment (attitude, velocity, position, uncertainty).
  /// After a start that only looked still, the dead-reckoned past moves with it as a world
  /// correction (what follows the frontend's world follows it); a moving start's positions were
  /// held at the fixes, so its world stays.
  void apply_in_motion_alignment(const estimate::InMotionAlignment& alignment, const Eigen::Vector3d& lever);
  /// The wheels' latest reading (at most 0.5 s old) showed no motion, in a start that was not moving.
  bool standing_still() const;
  /// A moving start before its alignment: the position is put at the GNSS fix (the dead-reckoned
  /// one, from an unknown velocity, would be worse than the fix).
  void hold_at_fix(const Eigen::Vector3d& antenna_gnss, const Eigen::Matrix3d& covariance, const Eigen::Vector3d& lever);
  EventOutcome process_radar(const Event& event, const msgs::RadarMessage& radar, UpdateObserver* observer);
  // A rangefinder looking down measures the height above the floor (estimate/range_models.hpp):
  // the floor's height is placed where the estimate puts it at the first reading, and again
  // after kFloorStepSeconds of readings that disagree (a step, a table, stairs).
  EventOutcome process_range(const Event& event, const msgs::RangeMessage& range, UpdateObserver* observer);
  EventOutcome process_pose(const Event& event, const PoseMeasurement& pose, UpdateObserver* observer);
  void initialize(const Event& event, const msgs::ImuMessage& imu);
  /// Resets the filter to `state` (its timestamp: the start) with the initial covariance of
  /// the configuration and these sigmas.
  void start(const estimate::NavigationState& state, const Eigen::Matrix3d& position_covariance, const Eigen::Vector3d& velocity_sigma,
             double accel_bias_sigma, double gyro_bias_sigma);
  /// filter_->reset(); the map frames go with the old covariance (the next map pose of each
  /// sensor defines its frame again at the estimate).
  void reset_filter(const estimate::NavigationState& state, const estimate::ErrorCovariance& covariance);
  /// Without an IMU: starts the filter at the first event (see the class comment).
  void initialize_without_imu(const Event& event);
  /// Without an IMU: the virtual IMU sample of the motion model at the current estimate.
  estimate::ImuSample motion_model_sample() const;
  /// The latest accepted gyro reading, for models that need the body rate.
  // A fused sensor velocity with the body's angular rate now (bias removed), for the graph.
  FusedVelocity fused_velocity(const Event& event, const Eigen::Vector3d& velocity_sensor, const Eigen::Matrix3d& covariance) const;
  estimate::GyroReading gyro_reading() const;
  /// Propagates the filter to t with the last IMU sample held (without an IMU: by the motion
  /// model, in steps of at most 10 ms).
  void predict_to(Timestamp t);
  /// Runs one update (gated unless `gated` is false) and reports it; true when applied.
  /// channel: which of the sensor's updates this is (0, or 1 for a wheel's separate yaw rate),
  /// so that each is tracked for gate recovery on its own.
  bool update(const Event& event, const estimate::MeasurementModel& model, UpdateObserver* observer, std::optional<Rejection>* reason,
              int channel = 0, bool gated = true);
  /// update() for any filter operation: apply(gate) runs it with or without the gate.
  bool update_with(const Event& event, std::string_view model_name, const std::function<estimate::UpdateOutcome(bool)>& apply,
                   UpdateObserver* observer, std::optional<Rejection>* reason, int channel, bool gated);
  /// A pose in the sensor's own map frame: the first one defines the frame at the estimate.
  EventOutcome process_map_pose(const Event& event, const PoseMeasurement& pose, UpdateObserver* observer);
  void apply_constraints(const Event& event);
  /// A keyframe when keyframe_interval has passed since the previous one (IMU events only).
  std::optional<msgs::Keyframe> maybe_keyframe(Timestamp time);

  config::FrontendConfig frontend_;
  std::vector<SensorSetup> sensors_;
  std::optional<size_t> imu_sensor_;  ///< none: the motion model propagates
  estimate::FilterConfig filter_config_;
  std::unique_ptr<estimate::Filter> filter_;
  estimate::ImuSpikeFilter spike_filter_;

  bool initialized_ = false;
  Timestamp time_;
  std::optional<estimate::ImuSample> last_imu_;
  std::vector<estimate::ImuSample> alignment_samples_;
  std::vector<std::optional<msgs::WheelOdometryMessage>> previous_wheels_;
  std::vector<Timestamp> last_fused_;
  std::vector<Timestamp> gated_since_;  // per sensor and channel: start of the current run of gated updates
  std::optional<EnuFrame> enu_;
  /// The latest usable GNSS fix seen before initialization (sensor index, fix): with a
  /// configured datum it gives the initial position.
  std::optional<std::pair<size_t, msgs::GnssMessage>> gnss_before_initialization_;
  /// Wheel odometry showed motion during the alignment window (the IMU alone cannot tell a
  /// steady turn at constant speed from standing still with a gyro bias).
  bool wheels_moved_before_initialization_ = false;
  /// GNSS without an IMU heading: the world heading is unknown until the GNSS track and the
  /// dead-reckoned track over the same stretch can be compared (see align_heading_to_course).
  bool heading_pending_ = false;
  bool gnss_positions_to_backend_ = false;  // see set_gnss_positions_to_backend
  /// Without an IMU and without a sensor that measures the orientation (LiDAR, camera), the
  /// wheels' yaw rate is the only measurement of the turn: fused whatever use_yaw_rate says.
  bool wheel_yaw_rate_needed_ = false;
  /// Wheel odometry and a sensor that measures distance otherwise (GNSS, LiDAR, camera): the
  /// wheel speed scale state is estimated.
  bool estimate_wheel_scale_ = false;
  /// Besides, an IMU and the wheels' yaw rate fused (use_yaw_rate): the gyro's yaw-rate scale
  /// is estimated (the wheels' yaw rate measures the turn with the wheel scale, the gyro with its own).
  bool estimate_gyro_yaw_scale_ = false;
  /// An IMU and the wheels' yaw rate fused: the wheels' heading drift is estimated.
  bool estimate_wheel_heading_drift_ = false;
  struct CourseStart {
    Eigen::Vector3d antenna_gnss;      // ENU
    Eigen::Vector3d antenna_estimate;  // world, dead-reckoned
    bool averaged = false;             // the estimate there averaged GNSS fixes while standing still
  };
  std::optional<CourseStart> course_start_;
  /// The IMU's alignment window showed motion (or the wheels turned): the start velocity is
  /// unknown, so the heading comes from in-motion alignment; until then the position is held at
  /// each GNSS fix and wheels wait.
  bool moving_start_ = false;
  /// Frontend::resume: the state the filter starts at, without a static alignment.
  std::optional<msgs::PoseEstimate> resume_state_;
  /// While the heading is pending: the recent GNSS track (world) and IMU samples, and the
  /// wheels' latest forward speed (its sign says whether the vehicle reverses).
  std::vector<estimate::GnssTrackPoint> recent_fixes_;
  std::vector<estimate::ImuSample> recent_imu_;
  std::vector<std::pair<Timestamp, double>> recent_wheel_speeds_;  ///< forward speed, m/s
  double wheel_forward_speed_ = 0.0;
  /// The time of the latest wheel reading, when it showed no motion (cleared by one that did).
  std::optional<Timestamp> wheels_still_at_;
  double gravity_magnitude_ = estimate::kStandardGravity;
  struct KeyframeAnchor {
    uint64_t id = 0;
    Timestamp time;
    SE3 T_world_body;
    Eigen::Matrix<double, 6, 6> covariance;
  };
  std::optional<KeyframeAnchor> last_keyframe_;
  double planar_height_ = 0.0;
  Timestamp last_gravity_update_;
  SE3 world_correction_;
  /// Per sensor, its map frame once defined: the filter's index, or (filters without map
  /// frames) the frame fixed in the world where it was defined, moved by world corrections.
  struct MapLink {
    std::optional<int> frame;
    SE3 T_world_map;
  };
  std::vector<std::optional<MapLink>> map_links_;
  std::vector<std::optional<double>> floor_heights_;  // per sensor: a downward rangefinder's floor, world z
};

}  // namespace hanzo::fusion::pipeline
