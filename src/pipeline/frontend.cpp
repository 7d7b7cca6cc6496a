#include "hanzo/fusion/pipeline/frontend.hpp"

#include <algorithm>
#include <cmath>
#include <deque>
#include <set>

#include <fmt/format.h>

#include "estimator.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/msgs/validate.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using config::SensorModality;

// Modalities whose raw messages the frontend fuses itself (the others arrive as poses from
// their odometry modules through push_pose()).
bool fused_directly(SensorModality modality) {
  return modality == SensorModality::kImu || modality == SensorModality::kGnss || modality == SensorModality::kWheelOdometry ||
         modality == SensorModality::kRadar || modality == SensorModality::kRange;
}

}  // namespace

uint64_t SensorStatistics::rejected_total() const {
  uint64_t total = 0;
  for (const auto& [reason, count] : rejected) total += count;
  return total;
}

struct Frontend::Impl final : UpdateObserver {
  struct HistoryEntry {
    Event event;
    Estimator after;  // the estimator right after fusing event
  };

  // sensor_setups[i].config is set here to point into this Impl's own configuration.
  Impl(config::FusionConfig fusion_config, std::vector<SensorSetup> sensor_setups, std::optional<size_t> imu)
      : config(std::move(fusion_config)), setups(link(std::move(sensor_setups), config)), imu_sensor(imu),
        estimator(config, setups, imu_sensor), history_base(estimator) {
    for (const SensorSetup& setup : setups) {
      SensorStatistics statistics;
      statistics.name = setup.config->name;
      statistics.modality = setup.config->modality;
      sensors.push_back(std::move(statistics));
    }
    last_input.resize(setups.size());
    last_heard.resize(setups.size());
  }

  static std::vector<SensorSetup> link(std::vector<SensorSetup> sensor_setups, const config::FusionConfig& fusion_config) {
    for (size_t i = 0; i < sensor_setups.size(); ++i) sensor_setups[i].config = &fusion_config.sensors[i];
    return sensor_setups;
  }

  void on_update(const UpdateReport& report) override {
    if (replaying) return;
    SensorStatistics& statistics = sensors[report.sensor];
    const bool applied = report.outcome.status == estimate::UpdateStatus::kApplied;
    if (applied) {
      statistics.nis_sum += report.outcome.mahalanobis_squared;
      statistics.nis_count += static_cast<uint64_t>(report.outcome.innovation.size());
    }
    if (innovation_callback) {
      const auto& innovation = report.outcome.innovation;
      innovation_callback({statistics.name, report.model, report.time,
                           std::vector<double>(innovation.data(), innovation.data() + innovation.size()),
                           report.outcome.mahalanobis_squared, applied});
    }
  }

  std::optional<size_t> sensor_index(std::string_view name) const {
    for (size_t i = 0; i < config.sensors.size(); ++i) {
      if (config.sensors[i].name == name) return i;
    }
    return std::nullopt;
  }
  /// Sets *sensor (its index) when the checks pass.
  PushStatus pose_input(size_t* sensor, std::string_view sensor_name, std::string_view what, Timestamp timestamp, const SE3& pose,
                            const Eigen::Matrix<double, 6, 6>& covariance, const std::function<Status()>& extra);
  PushStatus accept(size_t sensor, Event event);
  /// pose_input()'s checks, then the measurement into the time order (push_pose, push_map_pose).
  PushStatus push_pose_measurement(std::string_view sensor_name, std::string_view what, Timestamp timestamp, PoseMeasurement measurement);
  void fuse_in_order(Event event);
  void fuse_late(Event event);
  /// Holds a keyframe the estimator made (a newer version of one held replaces it: a late
  /// message re-made it) until send_final_keyframes() sends it.
  void hold_keyframe(const msgs::Keyframe& keyframe);
  /// Sends the held keyframes no late message can change any more (the filter passed them by
  /// more than the lag window; all of them when `all`), moved into today's world.
  void send_final_keyframes(bool all);
  /// Reports a fused GNSS fix or sensor velocity (first fusions only: fuse_in_order and a late
  /// event itself; a replay after a rollback re-fuses measurements already reported).
  void report_fused(const Event& event, const EventOutcome& outcome);
  void count(const Event& event, const EventOutcome& outcome);
  /// Fuses the pending messages up to the IMU's time (all of them when flush_all).
  void release_pending(bool flush_all = false);
  void prune_history();
  /// Records the PoseEstimate at the estimator's time as latest_pose; calls the pose callback
  /// when notify (not for poses recomputed while re-fusing after a late message) and the pose
  /// is newer than the last one the callback got (the pose stream stays in time order).
  /// A pose emitted for a gated measurement (the motion model's prediction) is DEGRADED.
  void emit_pose(bool notify, bool gated = false);
  void update_timeouts();
  /// Poses come from fused IMU messages; without an IMU from every measurement fused or gated
  /// (a gated one's pose is the motion model's prediction at its time, emitted DEGRADED: the
  /// pose stream does not thin out where a sensor disagrees), not from motion-model ticks.
  bool emits_pose(const Event& event, const EventOutcome& outcome) const {
    if (!estimator.initialized()) return false;
    if (imu_sensor) return outcome.fused && event.is_imu;
    if (!outcome.fused && !gated(outcome)) return false;
    return std::holds_alternative<msgs::SensorMessage>(event.payload) || std::holds_alternative<PoseMeasurement>(event.payload) ||
           std::holds_alternative<VelocityMeasurement>(event.payload);
  }
  static bool gated(const EventOutcome& outcome) { return !outcome.fused && outcome.reason == Rejection::kGated; }
  msgs::PoseStatus pose_status() const;

  config::FusionConfig config;
  std::vector<SensorSetup> setups;
  std::optional<size_t> imu_sensor;  // none: the motion model propagates (Estimator)
  Estimator estimator;
  Estimator history_base;  // the estimator before the oldest history entry
  std::deque<HistoryEntry> history;
  std::vector<Event> pending;  // accepted, waiting for the IMU to reach their time (sorted)
  std::vector<SensorStatistics> sensors;
  std::vector<Timestamp> last_input;  // last accepted body-clock time per sensor
  std::vector<Timestamp> last_heard;  // last body-clock time each sensor was heard (accepted or noted): its timeout
  double timeout_grace_s = 0.0;       // set_timeout_grace()
  Timestamp first_input;
  Timestamp newest;
  std::optional<Timestamp> pending_jump;
  uint64_t sequence = 0;
  bool replaying = false;
  uint64_t poses = 0;
  uint64_t rollbacks = 0;
  uint64_t zero_velocity_updates = 0;
  std::optional<msgs::PoseEstimate> latest_pose;
  std::optional<Timestamp> last_notified;  // the newest pose the callback got
  PoseCallback pose_callback;
  InnovationCallback innovation_callback;
  KeyframeCallback keyframe_callback;
  GnssCallback gnss_callback;
  VelocityCallback velocity_callback;
  // Emitted keyframes, for corrections: the pose before any correction (C^-1 x emitted pose,
  // C the world correction when it was emitted), so that today's belief is C_now x this.
  std::map<uint64_t, SE3> keyframe_poses;
  struct HeldKeyframe {
    msgs::Keyframe keyframe;
    SE3 world_correction;  // the estimator's when it made the keyframe
  };
  std::map<uint64_t, HeldKeyframe> held_keyframes;
  uint64_t keyframes = 0;
  uint64_t corrections = 0;
};

Frontend::Frontend(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Frontend::~Frontend() = default;

Result<std::unique_ptr<Frontend>> Frontend::create(const config::FusionConfig& config, const calib::Calibration& calibration) {
  if (Status valid = config::validate(config); !valid) return valid.error();
  if (Status valid = calib::validate(calibration); !valid) return valid.error();
  if (config.sensors.empty()) return Error("the configuration has no sensors: nothing to fuse", "sensors");
  // A calibration that leaves a sensor out is refused: a silent identity mounting would skew
  // every measurement of that sensor. Without any calibration every sensor is at the origin.
  if (calibration.sensors.empty()) logger()->warn("no calibration: every sensor is mounted at the body origin with no time offset");
  std::vector<SensorSetup> setups;
  std::optional<size_t> imu;
  for (const config::SensorConfig& sensor : config.sensors) {
    if (sensor.modality == SensorModality::kImu && !imu) imu = setups.size();
    SensorSetup setup;
    const calib::SensorCalibration* entry = calibration.find(sensor.name);
    if (entry != nullptr) {
      setup.T_body_sensor = entry->T_body_sensor();
      setup.time_offset = entry->time_offset;
    } else if (!calibration.sensors.empty()) {
      return Error(fmt::format("the calibration has no '{0}_to_body' entry for sensor '{0}' (write its mounting, or '{0}_to_body: identity' "
                               "for the body origin)",
                               sensor.name),
                   sensor.name + "_to_body");
    }
    if (sensor.modality == SensorModality::kCamera && (entry == nullptr || !entry->camera)) {
      return Error(fmt::format("camera '{0}' has no intrinsics: add 'intrinsics:' (fx, fy, cx, cy, width, height) to '{0}_to_body' in the "
                               "calibration",
                               sensor.name),
                   sensor.name + "_to_body.intrinsics");
    }
    setups.push_back(setup);
  }
  if (!imu) logger()->info("no IMU sensor: the frontend propagates with a constant-velocity motion model");
  return std::unique_ptr<Frontend>(new Frontend(std::make_unique<Impl>(config, std::move(setups), imu)));
}

const config::SensorConfig* Frontend::sensor_for_topic(std::string_view topic) const {
  for (const config::SensorConfig& sensor : impl_->config.sensors) {
    if (sensor.topic == topic) return &sensor;
  }
  if (topic.ends_with(config::kDetectionsTopicSuffix)) {
    const std::string_view camera_topic = topic.substr(0, topic.size() - config::kDetectionsTopicSuffix.size());
    for (const config::SensorConfig& sensor : impl_->config.sensors) {
      if (sensor.modality == config::SensorModality::kCamera && sensor.topic == camera_topic) return &sensor;
    }
  }
  return nullptr;
}

const config::FusionConfig& Frontend::config() const { return impl_->config; }
void Frontend::set_pose_callback(PoseCallback callback) { impl_->pose_callback = std::move(callback); }
void Frontend::set_innovation_callback(InnovationCallback callback) { impl_->innovation_callback = std::move(callback); }
void Frontend::set_keyframe_callback(KeyframeCallback callback) { impl_->keyframe_callback = std::move(callback); }
void Frontend::set_gnss_callback(GnssCallback callback) { impl_->gnss_callback = std::move(callback); }
void Frontend::set_velocity_callback(VelocityCallback callback) { impl_->velocity_callback = std::move(callback); }
void Frontend::set_gnss_positions_to_backend(bool enabled) {
  // The history's estimators too: a rollback restarts from one of them.
  impl_->estimator.set_gnss_positions_to_backend(enabled);
  for (Impl::HistoryEntry& entry : impl_->history) entry.after.set_gnss_positions_to_backend(enabled);
}

Status Frontend::apply_correction(uint64_t keyframe_id, const SE3& T_world_body_optimized) {
  Impl& impl = *impl_;
  const auto found = impl.keyframe_poses.find(keyframe_id);
  if (found == impl.keyframe_poses.end()) {
    return Error(fmt::format("unknown_keyframe: keyframe {} was not emitted by this frontend (or is too old)", keyframe_id));
  }
  if (!T_world_body_optimized.translation().allFinite() || !T_world_body_optimized.rotation().quaternion().coeffs().allFinite()) {
    return Error("invalid: the optimized pose has non-finite values");
  }
  Event event;
  // At the newest fused event (the estimator's time can trail it: rejected events do not move
  // it), so the correction goes to the end of the history.
  event.time = impl.history.empty() ? impl.estimator.time() : std::max(impl.estimator.time(), impl.history.back().event.time);
  event.sensor = impl.imu_sensor.value_or(0);
  event.sequence = impl.sequence++;
  // The session's current belief of the keyframe includes the corrections applied since.
  event.payload = WorldCorrection{T_world_body_optimized * (impl.estimator.world_correction() * found->second).inverse()};
  impl.fuse_in_order(std::move(event));
  ++impl.corrections;
  // latest_pose() answers in the corrected world at once; the next IMU sample emits it.
  if (impl.estimator.initialized()) impl.emit_pose(false);
  return ok_status();
}
std::optional<msgs::PoseEstimate> Frontend::latest_pose() const { return impl_->latest_pose; }
SE3 Frontend::world_correction() const { return impl_->estimator.world_correction(); }

std::optional<std::pair<Eigen::Vector3d, Eigen::Vector3d>> Frontend::imu_bias() const {
  if (!has_imu() || !impl_->estimator.initialized()) return std::nullopt;
  const estimate::NavigationState state = impl_->estimator.filter().state();
  return std::make_pair(state.accel_bias, state.gyro_bias);
}

std::optional<SE3> Frontend::pose_at(Timestamp time) const {
  // In today's world: corrections fused after the entry move it too.
  const SE3& correction_now = impl_->estimator.world_correction();
  const auto pose_of = [&correction_now](const Estimator& estimator) {
    const estimate::NavigationState state = estimator.filter().state();
    return correction_now * estimator.world_correction().inverse() * SE3(state.R_world_body, state.position);
  };
  const std::deque<Impl::HistoryEntry>& history = impl_->history;
  // history is in fusion order, so its times do not decrease; the first entry at or after `time`.
  const auto after = std::lower_bound(history.begin(), history.end(), time,
                                      [](const Impl::HistoryEntry& entry, Timestamp t) { return entry.event.time < t; });
  if (after == history.end() || !after->after.initialized()) return std::nullopt;
  if (after->event.time == time) return pose_of(after->after);
  if (after == history.begin()) return std::nullopt;
  const auto before = std::prev(after);
  if (!before->after.initialized()) return std::nullopt;
  const double span = (after->event.time - before->event.time).seconds();
  const double fraction = span > 0.0 ? (time - before->event.time).seconds() / span : 1.0;
  return SE3::interpolate(pose_of(before->after), pose_of(after->after), fraction);
}

PushStatus Frontend::push(std::string_view sensor_name, const msgs::SensorMessage& message) {
  Impl& impl = *impl_;
  const std::optional<size_t> index = impl.sensor_index(sensor_name);
  if (!index) return PushStatus(Rejection::kUnknownSensor, fmt::format("no sensor named '{}' in the configuration", sensor_name));
  const size_t sensor = *index;
  const config::SensorConfig* found = &impl.config.sensors[sensor];
  SensorStatistics& statistics = impl.sensors[sensor];
  ++statistics.received;
  if (config::modality_of(message) != found->modality) {
    ++statistics.rejected[Rejection::kWrongType];
    return PushStatus(Rejection::kWrongType, fmt::format("sensor '{}' is a {} sensor, the message is {}", sensor_name,
                                               config::to_string(found->modality), msgs::modality_name(message)));
  }
  if (Status valid = msgs::validate(message); !valid) {
    ++statistics.rejected[Rejection::kInvalid];
    return PushStatus(Rejection::kInvalid, fmt::format("{}: {}", sensor_name, valid.error().message));
  }
  Event event;
  event.time = msgs::timestamp_of(message) + impl.setups[sensor].time_offset;
  event.sensor = sensor;
  event.is_imu = found->modality == SensorModality::kImu;
  event.payload = message;
  return impl.accept(sensor, std::move(event));
}

// The checks push_pose() and push_relative_pose() share: the sensor exists (counted as received),
// the pose is valid and the covariance positive definite. `extra` adds checks of its own.
PushStatus Frontend::Impl::pose_input(size_t* sensor, std::string_view sensor_name, std::string_view what, Timestamp timestamp, const SE3& pose,
                                         const Eigen::Matrix<double, 6, 6>& covariance, const std::function<Status()>& extra) {
  const std::optional<size_t> index = sensor_index(sensor_name);
  if (!index) return PushStatus(Rejection::kUnknownSensor, fmt::format("no sensor named '{}' in the configuration", sensor_name));
  ++sensors[*index].received;
  msgs::PoseEstimate as_message;  // validate() checks the pose and covariance the same way
  as_message.timestamp = timestamp;
  as_message.T_world_body = msgs::Pose::from_se3(pose);
  as_message.pose_covariance = covariance;
  Status valid = msgs::validate(as_message);
  if (valid && extra) valid = extra();
  if (valid && covariance.llt().info() != Eigen::Success) valid = Error("covariance is not positive definite");
  if (!valid) {
    ++sensors[*index].rejected[Rejection::kInvalid];
    return PushStatus(Rejection::kInvalid, fmt::format("{}: {}: {}", sensor_name, what, valid.error().message));
  }
  *sensor = *index;
  return {};
}

PushStatus Frontend::Impl::push_pose_measurement(std::string_view sensor_name, std::string_view what, Timestamp timestamp,
                                                  PoseMeasurement measurement) {
  size_t sensor = 0;
  if (PushStatus checked = pose_input(&sensor, sensor_name, what, timestamp, measurement.T_world_sensor, measurement.covariance, {}); !checked) {
    return checked;
  }
  Event event;
  event.time = timestamp + setups[sensor].time_offset;
  event.sensor = sensor;
  event.payload = std::move(measurement);
  return accept(sensor, std::move(event));
}

PushStatus Frontend::push_pose(std::string_view sensor_name, Timestamp timestamp, const SE3& T_world_sensor,
                          const Eigen::Matrix<double, 6, 6>& covariance, bool gated) {
  return impl_->push_pose_measurement(sensor_name, "pose measurement", timestamp, PoseMeasurement{T_world_sensor, covariance, gated});
}

PushStatus Frontend::push_map_pose(std::string_view sensor_name, Timestamp timestamp, const SE3& T_map_sensor,
                                   const Eigen::Matrix<double, 6, 6>& covariance) {
  return impl_->push_pose_measurement(sensor_name, "map pose measurement", timestamp, PoseMeasurement{T_map_sensor, covariance, true, true});
}

std::optional<SE3> Frontend::map_frame(std::string_view sensor_name) const {
  const std::optional<size_t> index = impl_->sensor_index(sensor_name);
  if (!index) return std::nullopt;
  return impl_->estimator.map_frame(*index);
}

PushStatus Frontend::push_relative_pose(std::string_view sensor_name, Timestamp from, Timestamp to, const SE3& T_from_to,
                                   const Eigen::Matrix<double, 6, 6>& covariance) {
  Impl& impl = *impl_;
  const double dt = (to - from).seconds();
  const auto interval = [&]() -> Status {
    if (from.is_zero()) return Error("the start time is zero");
    if (!(dt > 0.0)) return Error(fmt::format("the interval must be positive, got {} s", dt));
    return ok_status();
  };
  size_t sensor = 0;
  if (PushStatus checked = impl.pose_input(&sensor, sensor_name, "relative pose", to, T_from_to, covariance, interval); !checked) {
    return checked;
  }
  const Eigen::Matrix3d R_to_from = T_from_to.rotation().matrix().transpose();
  Event event;
  event.time = to + impl.setups[sensor].time_offset;
  event.sensor = sensor;
  event.payload = VelocityMeasurement{R_to_from * T_from_to.translation() / dt, covariance.topLeftCorner<3, 3>() / (dt * dt)};
  return impl.accept(sensor, std::move(event));
}

void Frontend::note_input(std::string_view sensor_name, Timestamp time) {
  Impl& impl = *impl_;
  const std::optional<size_t> index = impl.sensor_index(sensor_name);
  if (!index) return;
  const Timestamp body_time = time + impl.setups[*index].time_offset;
  if (body_time > impl.last_heard[*index]) impl.last_heard[*index] = body_time;
}

void Frontend::set_timeout_grace(double seconds) { impl_->timeout_grace_s = std::max(0.0, seconds); }

void Frontend::resume(const msgs::PoseEstimate& state) {
  // The history's estimators too: a rollback restarts from one of them.
  impl_->estimator.resume_from(state);
  impl_->history_base.resume_from(state);
  for (Impl::HistoryEntry& entry : impl_->history) entry.after.resume_from(state);
}

PushStatus Frontend::Impl::accept(size_t sensor, Event event) {
  SensorStatistics& statistics = sensors[sensor];
  const std::string& name = statistics.name;
  const Timestamp previous = last_input[sensor];
  if (!previous.is_zero() && event.time == previous) {
    ++statistics.rejected[Rejection::kDuplicate];
    return PushStatus(Rejection::kDuplicate, fmt::format("{}: a message at {} ns was already received", name, event.time.nanoseconds()));
  }
  if (!previous.is_zero() && event.time < previous) {
    ++statistics.rejected[Rejection::kOutOfOrder];
    return PushStatus(Rejection::kOutOfOrder, fmt::format("{}: message at {} ns is {:.6f} s older than the sensor's previous one", name,
                                                 event.time.nanoseconds(), (previous - event.time).seconds()));
  }
  const double max_future = config.frontend.max_future_s;
  if (!newest.is_zero() && (event.time - newest).seconds() > max_future) {
    const bool confirmed = pending_jump && std::abs((event.time - *pending_jump).seconds()) <= max_future;
    if (!confirmed) {
      pending_jump = event.time;
      ++statistics.rejected[Rejection::kFutureDated];
      return PushStatus(Rejection::kFutureDated, fmt::format("{}: message at {} ns is {:.3f} s ahead of the newest accepted time (limit {} s)", name,
                                                   event.time.nanoseconds(), (event.time - newest).seconds(), max_future));
    }
    logger()->warn("time jumped forward by {:.3f} s (confirmed by two messages)", (event.time - newest).seconds());
  }
  pending_jump.reset();
  const double lag = config.frontend.lag_window_s;
  if (estimator.initialized() && (estimator.time() - event.time).seconds() > lag) {
    ++statistics.rejected[Rejection::kTooLate];
    return PushStatus(Rejection::kTooLate, fmt::format("{}: message at {} ns is {:.3f} s older than the newest fused time (lag window {} s)", name,
                                             event.time.nanoseconds(), (estimator.time() - event.time).seconds(), lag));
  }

  last_input[sensor] = event.time;
  last_heard[sensor] = std::max(last_heard[sensor], event.time);
  if (statistics.first_time.is_zero()) statistics.first_time = event.time;
  statistics.last_time = event.time;
  if (first_input.is_zero()) first_input = event.time;
  newest = std::max(newest, event.time);
  const bool is_pose = !std::holds_alternative<msgs::SensorMessage>(event.payload);
  if (!is_pose && !fused_directly(statistics.modality)) {
    ++statistics.rejected[Rejection::kNotFused];
    return {};
  }
  event.sequence = sequence++;
  // Late: it belongs before something already fused (the history is in fusion order). Not
  // estimator.time(): events that change nothing (before the IMU aligned, a rejected spike)
  // leave it behind, and appending an older event then would unsort the history.
  if (!history.empty() && fused_before(event, history.back().event)) {
    fuse_late(std::move(event));
  } else {
    pending.insert(std::upper_bound(pending.begin(), pending.end(), event, fused_before), std::move(event));
  }
  release_pending();
  return {};
}

void Frontend::flush() { impl_->release_pending(true); }

bool Frontend::has_imu() const { return impl_->imu_sensor.has_value(); }

void Frontend::propagate_to(Timestamp time) {
  Impl& impl = *impl_;
  if (impl.imu_sensor || time.is_zero()) return;
  if (!impl.history.empty() && time <= impl.history.back().event.time) return;
  Event event;
  event.time = time;
  event.sequence = impl.sequence++;
  event.is_imu = true;  // a clock event: before measurements at the same time
  event.payload = MotionTick{};
  impl.fuse_in_order(std::move(event));
  impl.prune_history();
  impl.send_final_keyframes(false);
}

void Frontend::Impl::release_pending(bool flush_all) {
  // Measurements wait for the IMU to reach their time; when the IMU is silent they go ahead.
  // Without an IMU nothing waits (each measurement moves the motion model to its own time).
  Timestamp release = newest;
  if (imu_sensor && !flush_all) {
    const Timestamp imu_time = last_input[*imu_sensor];
    const bool imu_silent = imu_time.is_zero() || (newest - imu_time).seconds() > setups[*imu_sensor].config->effective_timeout_s();
    if (!imu_silent) release = imu_time;
  }
  size_t released = 0;
  while (released < pending.size() && pending[released].time <= release) ++released;
  if (released > 0) {
    std::vector<Event> ready(std::make_move_iterator(pending.begin()), std::make_move_iterator(pending.begin() + static_cast<std::ptrdiff_t>(released)));
    pending.erase(pending.begin(), pending.begin() + static_cast<std::ptrdiff_t>(released));
    for (Event& event : ready) fuse_in_order(std::move(event));
    prune_history();
  }
  send_final_keyframes(flush_all);
}

void Frontend::Impl::count(const Event& event, const EventOutcome& outcome) {
  // A backend correction rides on the IMU sensor's index but is no message of it (`corrections`);
  // a motion-model tick is no message either.
  if (std::holds_alternative<WorldCorrection>(event.payload) || std::holds_alternative<MotionTick>(event.payload)) return;
  SensorStatistics& statistics = sensors[event.sensor];
  if (outcome.fused) {
    ++statistics.fused;
  } else {
    ++statistics.rejected[outcome.reason.value_or(Rejection::kNotFused)];
  }
  if (outcome.zero_velocity_update) ++zero_velocity_updates;
}

void Frontend::Impl::fuse_in_order(Event event) {
  const EventOutcome outcome = estimator.process(event, this);
  count(event, outcome);
  if (config.frontend.lag_window_s > 0.0) history.push_back({event, estimator});
  if (emits_pose(event, outcome)) emit_pose(true, gated(outcome));
  if (outcome.keyframe) hold_keyframe(*outcome.keyframe);
  report_fused(event, outcome);
}

void Frontend::Impl::report_fused(const Event& event, const EventOutcome& outcome) {
  if (outcome.velocity && velocity_callback) {
    FusedVelocity velocity = *outcome.velocity;
    velocity.sensor = sensors[event.sensor].name;
    velocity_callback(velocity);
  }
  if (!outcome.gnss_fix || !gnss_callback) return;
  FusedGnssFix fix = *outcome.gnss_fix;
  fix.sensor = sensors[event.sensor].name;
  gnss_callback(fix);
}

void Frontend::Impl::hold_keyframe(const msgs::Keyframe& keyframe) {
  // Sent keyframes are final (a message that could re-make one is too late).
  if (!keyframe_poses.empty() && keyframe.keyframe_id <= keyframe_poses.rbegin()->first) return;
  held_keyframes[keyframe.keyframe_id] = {keyframe, estimator.world_correction()};
}

void Frontend::Impl::send_final_keyframes(bool all) {
  // A keyframe sent while a late message could still re-make it would give the backend the
  // pose before that message (e.g. before the LiDAR pose of a sweep registered after the IMU
  // passed it) and the next keyframe's relative motion from the pose after it: the difference
  // would accumulate in the graph's chain of relative motions.
  const double lag = config.frontend.lag_window_s;
  while (!held_keyframes.empty()) {
    const auto oldest = held_keyframes.begin();
    if (!all && (estimator.time() - oldest->second.keyframe.timestamp).seconds() <= lag) return;
    msgs::Keyframe keyframe = std::move(oldest->second.keyframe);
    const SE3 made_in = oldest->second.world_correction;
    held_keyframes.erase(oldest);
    const SE3 T_world_body = keyframe.T_world_body.to_se3();
    // Backend corrections since the keyframe was made move it into today's world (its
    // relative motion does not change).
    const SE3 moved = estimator.world_correction() * made_in.inverse();
    keyframe.T_world_body = msgs::Pose::from_se3(moved * T_world_body);
    keyframe.velocity = moved.rotation() * keyframe.velocity;
    if (keyframe.pose_covariance) {
      Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Identity();
      J.topLeftCorner<3, 3>() = moved.rotation().matrix();  // (position world, orientation body)
      keyframe.pose_covariance = msgs::Matrix6d(J * *keyframe.pose_covariance * J.transpose());
    }
    constexpr size_t kRememberedKeyframes = 100000;
    keyframe_poses[keyframe.keyframe_id] = made_in.inverse() * T_world_body;
    if (keyframe_poses.size() > kRememberedKeyframes) keyframe_poses.erase(keyframe_poses.begin());
    ++keyframes;
    if (keyframe_callback) keyframe_callback(keyframe);
  }
}

void Frontend::Impl::fuse_late(Event event) {
  // Restore the estimator from just before the late event, fuse it, then re-fuse what followed.
  const auto position = std::upper_bound(history.begin(), history.end(), event,
                                         [](const Event& e, const HistoryEntry& entry) { return fused_before(e, entry.event); });
  const size_t index = static_cast<size_t>(position - history.begin());
  estimator = index == 0 ? history_base : history[index - 1].after;
  const EventOutcome outcome = estimator.process(event, this);
  count(event, outcome);
  // A late IMU message (its stream fell behind another sensor's, which was fused ahead of it)
  // still gets its pose, as of its own time: poses come from IMU messages only, and those
  // arrive in order, so the pose stream stays in time order. Without an IMU a late
  // measurement gets its pose when it is newer than the last one emitted (emit_pose).
  if (emits_pose(event, outcome)) emit_pose(true, gated(outcome));
  // It can make a keyframe, and so can the messages re-fused after it: held until final.
  if (outcome.keyframe) hold_keyframe(*outcome.keyframe);
  report_fused(event, outcome);
  ++sensors[event.sensor].rolled_back;
  ++rollbacks;
  history.insert(history.begin() + static_cast<std::ptrdiff_t>(index), HistoryEntry{event, estimator});
  replaying = true;
  for (size_t i = index + 1; i < history.size(); ++i) {
    const EventOutcome again = estimator.process(history[i].event, nullptr);
    history[i].after = estimator;
    if (emits_pose(history[i].event, again)) emit_pose(false, gated(again));
    if (again.keyframe) hold_keyframe(*again.keyframe);
  }
  replaying = false;
}

void Frontend::Impl::prune_history() {
  const double lag = config.frontend.lag_window_s;
  while (!history.empty() && (history.back().event.time - history.front().event.time).seconds() > lag) {
    history_base = std::move(history.front().after);
    history.pop_front();
  }
}

void Frontend::Impl::update_timeouts() {
  for (size_t i = 0; i < sensors.size(); ++i) {
    const Timestamp reference = last_heard[i].is_zero() ? first_input : last_heard[i];
    const double timeout = setups[i].config->effective_timeout_s() + timeout_grace_s;
    const bool silent = (newest - reference).seconds() > timeout;
    if (silent && !sensors[i].timed_out) {
      ++sensors[i].timeouts;
      logger()->warn("sensor '{}' timed out: silent for more than {} s; fusing the other sensors", sensors[i].name, timeout);
    }
    sensors[i].timed_out = silent;
  }
}

msgs::PoseStatus Frontend::Impl::pose_status() const {
  msgs::PoseStatus status;
  std::set<SensorModality> modalities;
  bool any_timed_out = false;
  for (size_t i = 0; i < sensors.size(); ++i) {
    any_timed_out = any_timed_out || sensors[i].timed_out;
    const Timestamp fused = estimator.last_fused()[i];
    if (fused.is_zero() || (estimator.time() - fused).seconds() > setups[i].config->effective_timeout_s()) continue;
    modalities.insert(sensors[i].modality);
    status.active_sensors.push_back(sensors[i].name);
  }
  status.active_modalities = static_cast<uint32_t>(modalities.size());
  if (!estimator.initialized() || !estimator.heading_known()) {
    status.state = msgs::TrackingState::kInitializing;
  } else if (imu_sensor ? sensors[*imu_sensor].timed_out : status.active_modalities == 0) {
    status.state = msgs::TrackingState::kLost;
  } else if (any_timed_out || !status.localization_reliable()) {
    status.state = msgs::TrackingState::kDegraded;
  } else {
    status.state = msgs::TrackingState::kTracking;
  }
  return status;
}

void Frontend::Impl::emit_pose(bool notify, bool gated) {
  update_timeouts();
  const estimate::NavigationState state = estimator.filter().state();
  const estimate::ErrorCovariance covariance = estimator.filter().covariance();
  msgs::PoseEstimate pose;
  pose.timestamp = estimator.time();
  pose.frame_id = msgs::kWorldFrame;
  pose.child_frame_id = msgs::kBodyFrame;
  pose.T_world_body = msgs::Pose::from_se3(SE3(state.R_world_body, state.position));
  pose.velocity = state.velocity;
  pose.pose_covariance = covariance.topLeftCorner<6, 6>();
  pose.status = pose_status();
  if (gated && pose.status.state == msgs::TrackingState::kTracking) pose.status.state = msgs::TrackingState::kDegraded;
  latest_pose = pose;
  if (!notify || (last_notified && pose.timestamp <= *last_notified)) return;
  last_notified = pose.timestamp;
  ++poses;
  if (pose_callback) pose_callback(pose);
}

SessionSummary Frontend::summary() const {
  SessionSummary summary;
  summary.sensors = impl_->sensors;
  summary.poses = impl_->poses;
  summary.rollbacks = impl_->rollbacks;
  summary.zero_velocity_updates = impl_->zero_velocity_updates;
  summary.keyframes = impl_->keyframes;
  summary.corrections = impl_->corrections;
  summary.filter = std::string(impl_->estimator.filter().name());
  // Now, not as of the latest pose: a sensor heard from again after that pose no longer counts
  // as timed out (the pose's own status stays as it was emitted).
  summary.state = impl_->latest_pose ? impl_->pose_status().state : msgs::TrackingState::kInitializing;
  if (impl_->estimator.initialized()) {
    const estimate::NavigationState& state = impl_->estimator.filter().state();
    const estimate::ErrorCovariance& P = impl_->estimator.filter().covariance();
    if (impl_->estimator.estimates_wheel_scale()) {
      summary.wheel_speed_scale = state.wheel_speed_scale;
      summary.wheel_speed_scale_sigma = std::sqrt(P(estimate::kWheelScaleIndex, estimate::kWheelScaleIndex));
    }
    if (impl_->estimator.estimates_gyro_yaw_scale()) {
      summary.gyro_yaw_scale = state.gyro_yaw_scale;
      summary.gyro_yaw_scale_sigma = std::sqrt(P(estimate::kGyroYawScaleIndex, estimate::kGyroYawScaleIndex));
    }
    if (impl_->estimator.estimates_wheel_heading_drift()) {
      summary.wheel_heading_drift = state.wheel_heading_drift;
      summary.wheel_heading_drift_sigma = std::sqrt(P(estimate::kWheelHeadingDriftIndex, estimate::kWheelHeadingDriftIndex));
    }
  }
  return summary;
}

}  // namespace hanzo::fusion::pipeline
