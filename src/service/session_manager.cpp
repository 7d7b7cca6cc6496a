#include "hanzo/fusion/service/session_manager.hpp"

#include <algorithm>
#include <filesystem>
#include <condition_variable>
#include <list>
#include <map>
#include <mutex>
#include <random>
#include <shared_mutex>
#include <thread>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "pose_recorder.hpp"

namespace hanzo::fusion::service {
namespace {

using Clock = std::chrono::steady_clock;

std::string generate_session_id() {
  static std::mutex mutex;
  static std::random_device device;
  static std::mt19937_64 generator(device() ^ (static_cast<uint64_t>(device()) << 32) ^
                                   static_cast<uint64_t>(Clock::now().time_since_epoch().count()));
  std::lock_guard lock(mutex);
  return fmt::format("{:016x}{:016x}", generator(), generator());
}

// The text of a YAML/JSON fragment as a node; the error names `what`.
Result<YAML::Node> parse_fragment(const std::string& text, const std::string& what) {
  try {
    return YAML::Load(text);
  } catch (const YAML::Exception& exception) {
    return Error(fmt::format("{}: not valid YAML/JSON: {}", what, exception.what()), what);
  }
}

std::string emit(const YAML::Node& node) {
  YAML::Emitter out;
  out << node;
  return out.c_str();
}

// Rebuilt configuration and calibration with one more sensor, validated by the file loaders.
Result<std::pair<config::FusionConfig, calib::Calibration>> with_sensor(const config::FusionConfig& configuration,
                                                                      const calib::Calibration& calibration,
                                                                      const SensorRegistration& registration) {
  if (registration.name.empty()) return Error("sensor name is empty", "name");
  YAML::Node config_node;
  HANZO_ASSIGN_OR_RETURN(config_node, parse_fragment(config::to_yaml(configuration), "configuration"));
  YAML::Node sensor_node;
  HANZO_ASSIGN_OR_RETURN(sensor_node, parse_fragment(registration.config_yaml, "config"));
  if (!sensor_node.IsMap()) return Error("config: expected the sensor's configuration entry (a map)", "config");
  config_node["fusion"]["sensors"][registration.name] = sensor_node;
  config::FusionConfig new_config;
  HANZO_ASSIGN_OR_RETURN(new_config, with_context(config::parse_fusion_config(emit(config_node), "sensor registration"), "config"));

  YAML::Node calibration_node;
  HANZO_ASSIGN_OR_RETURN(calibration_node, parse_fragment(calib::to_yaml(calibration), "calibration"));
  YAML::Node entry(YAML::NodeType::Map);
  if (!registration.calibration_yaml.empty()) {
    HANZO_ASSIGN_OR_RETURN(entry, parse_fragment(registration.calibration_yaml, "calibration"));
    if (!entry.IsMap()) return Error("calibration: expected the sensor's calibration entry (a map)", "calibration");
  }
  calibration_node["calibration"][registration.name + "_to_body"] = entry;
  // A session without a calibration runs its sensors at the body origin: they keep it, now said.
  for (const config::SensorConfig& sensor : configuration.sensors) {
    if (calibration.find(sensor.name) == nullptr) calibration_node["calibration"][sensor.name + "_to_body"] = YAML::Node(YAML::NodeType::Map);
  }
  calib::Calibration new_calibration;
  HANZO_ASSIGN_OR_RETURN(new_calibration,
                         with_context(calib::parse_calibration(emit(calibration_node), "sensor registration"), "calibration"));
  return std::make_pair(std::move(new_config), std::move(new_calibration));
}

// Adds a subscription of `capacity` to `subscribers`, dropping those their subscriber closed.
template <typename T>
std::shared_ptr<Subscription<T>> add_subscription(std::vector<std::shared_ptr<Subscription<T>>>& subscribers, std::size_t capacity) {
  std::erase_if(subscribers, [](const auto& subscriber) { return subscriber->closed(); });
  auto subscription = std::make_shared<Subscription<T>>(capacity);
  subscribers.push_back(subscription);
  return subscription;
}

double position_covariance_trace(const msgs::PoseEstimate& pose) {
  return pose.pose_covariance ? pose.pose_covariance->topLeftCorner<3, 3>().trace() : 0.0;
}

}  // namespace

// One server session: the pipeline::Session and what the server keeps around it.
struct ManagedSession {
  SessionRecord record;
  config::FusionConfig configuration;
  calib::Calibration calibration;

  std::mutex mutex;  // guards everything below
  std::unique_ptr<pipeline::Session> session;  // null once ended
  pipeline::SessionSummary final_summary;      // the session's summary when it ended
  pipeline::MappingSummary final_mapping;
  std::optional<msgs::FusionMap> final_map;    // the session's map when it ended (if it had one)
  std::optional<msgs::PoseEstimate> latest_pose;
  std::vector<std::shared_ptr<PoseSubscription>> pose_subscribers;
  std::vector<std::shared_ptr<KeyframeSubscription>> keyframe_subscribers;
  std::vector<std::shared_ptr<MapSubscription>> map_subscribers;
  bool map_updates_installed = false;  // the session's map update callback (only while subscribed)
  uint64_t messages_pushed = 0;
  Clock::time_point push_started;
  std::unique_ptr<SessionRecording> recording;  // raw sensor log, when the session records
  uint64_t saved_map_version = 0;   // the live map_version last saved to the map catalog
  uint64_t stored_map_version = 0;  // the catalog's version of that save (parent of the next)
  bool handed_over = false;  // moved to another replica: requests get kUnavailable

  // Metric series of the managed session (removed with it).
  Counter* poses = nullptr;
  Histogram* pose_latency = nullptr;
  Gauge* covariance_trace = nullptr;
  Gauge* tracking_state = nullptr;
};

struct SessionManager::Impl {
  SessionManagerConfig config;
  std::unique_ptr<Storage> storage;
  std::shared_ptr<MetricsRegistry> metrics;
  std::unique_ptr<detail::PoseRecorder> recorder;
  Gauge* active_sessions_gauge = nullptr;
  Counter* taken_over_counter = nullptr;
  Counter* lost_counter = nullptr;
  std::thread lease_keeper;             // replicas: keep_leases() every lease/3
  std::mutex locate_mutex;              // replicas: serializes locate()
  std::mutex keeper_mutex;
  std::condition_variable keeper_wake;
  bool keeper_stopping = false;

  mutable std::shared_mutex sessions_mutex;
  std::map<std::string, std::shared_ptr<ManagedSession>> sessions;  // active and ended

  std::unique_ptr<MapCatalog> catalog;  // null without a map directory
  std::mutex save_mutex;                // one map save at a time; taken before a session's mutex
  std::mutex saver_mutex;
  std::condition_variable saver_wake;
  bool saver_stopping = false;
  std::thread map_saver;                // saves changed session maps every map_save_interval
  std::mutex localizers_mutex;
  std::list<std::pair<std::string, std::shared_ptr<const lidar::MapLocalizer>>> localizers;  // "id@version", newest first

  // The caller holds `permission` and the server stores maps.
  ApiStatus may_use_maps(const Principal& caller, Permission permission) const {
    if (const ApiStatus allowed = authorize(caller, permission); !allowed) return allowed;
    if (catalog) return api_ok();
    return ApiError{ErrorCode::kUnavailable, "this server stores no maps (it runs without a map directory)", ""};
  }

  // Saves the session's map when it changed since the last save. Caller holds save_mutex and
  // `session_lock` (on managed.mutex); with release_while_writing the file is written without
  // the session's lock (the session keeps running meanwhile).
  ApiStatus save_map(ManagedSession& managed, std::unique_lock<std::mutex>& session_lock, bool release_while_writing) {
    if (!catalog || !managed.session) return api_ok();
    const pipeline::MappingSummary summary = managed.session->mapping_summary();
    if ((summary.map_keyframes == 0 && summary.visual_keyframes == 0) || summary.map_version == managed.saved_map_version) return api_ok();
    std::optional<msgs::FusionMap> map = map_locked(managed);
    if (!map) return api_ok();
    map->version = managed.stored_map_version;  // the parent of the new version
    const std::string organization = managed.record.organization, id = managed.record.id, name = managed.record.name;
    if (release_while_writing) session_lock.unlock();
    ApiResult<maps::MapVersionInfo> saved = catalog->save(organization, id, name, std::move(*map));
    if (release_while_writing) session_lock.lock();
    if (!saved) return saved.error();
    managed.saved_map_version = summary.map_version;
    managed.stored_map_version = saved->version;
    if (config.map_keep_versions > 0) {
      if (Result<std::size_t> pruned = catalog->prune(id, config.map_keep_versions); !pruned) {
        logger()->warn("maps: old versions of {} not pruned: {}", id, pruned.error().message);
      }
    }
    return api_ok();
  }

  void run_map_saver() {
    std::unique_lock lock(saver_mutex);
    while (!saver_wake.wait_for(lock, config.map_save_interval, [this] { return saver_stopping; })) {
      lock.unlock();
      if (const Status saved = save_all_maps(); !saved) logger()->warn("maps: {}", saved.error().message);
      lock.lock();
    }
  }

  Status save_all_maps() {
    std::vector<std::shared_ptr<ManagedSession>> active;
    {
      std::shared_lock lock(sessions_mutex);
      for (const auto& [id, managed] : sessions) active.push_back(managed);
    }
    std::string failures;
    for (const auto& managed : active) {
      std::lock_guard save_lock(save_mutex);
      std::unique_lock session_lock(managed->mutex);
      if (const ApiStatus saved = save_map(*managed, session_lock, true); !saved) {
        failures += fmt::format("{}map of session {} not saved: {}", failures.empty() ? "" : "; ", managed->record.id, saved.error().message);
      }
    }
    if (!failures.empty()) return Error(failures);
    return ok_status();
  }

  // A prepared localizer of a stored map version (kept for the next requests).
  ApiResult<std::shared_ptr<const lidar::MapLocalizer>> localizer(const std::string& organization, const std::string& map_id, uint64_t version) {
    const std::string key = fmt::format("{}@{}", map_id, version);
    {
      std::lock_guard lock(localizers_mutex);
      for (auto it = localizers.begin(); it != localizers.end(); ++it) {
        if (it->first != key) continue;
        localizers.splice(localizers.begin(), localizers, it);
        return localizers.front().second;
      }
    }
    ApiResult<msgs::FusionMap> map = catalog->load(organization, map_id, version);
    if (!map) return map.error();
    if (!map->points || map->points->points.empty()) {
      return ApiError{ErrorCode::kInvalidArgument, fmt::format("map '{}' version {} has no point layer to localize in", map_id, version), "map_id"};
    }
    auto created = lidar::MapLocalizer::create(std::move(map->points->points), {}, pipeline::SessionConfig().lidar_odometry.odometry);
    if (!created) return ApiError::from(ErrorCode::kInvalidArgument, created.error());
    auto prepared = std::make_shared<const lidar::MapLocalizer>(std::move(created).value());
    std::lock_guard lock(localizers_mutex);
    localizers.emplace_front(key, prepared);
    while (localizers.size() > std::max<std::size_t>(1, config.cached_localizers)) localizers.pop_back();
    return prepared;
  }

  // A pipeline::Session for `managed` with its callbacks wired (not yet installed; map
  // updates: sync_map_updates).
  Result<std::unique_ptr<pipeline::Session>> make_pipeline(ManagedSession& managed, const config::FusionConfig& configuration,
                                                                  const calib::Calibration& calibration) {
    pipeline::SessionConfig session_config = pipeline::SessionConfig::from(configuration);
    session_config.mode = pipeline::SessionMode::kRealtime;  // bounded latency: the IMU's poses never wait for a registration
    session_config.keep_trajectory = false;                  // the server stores the poses itself
    auto session = pipeline::Session::create(configuration, calibration, session_config);
    if (!session) return session.error();
    ManagedSession* raw = &managed;
    session.value()->set_pose_callback([this, raw](const msgs::PoseEstimate& pose) { on_pose(*raw, pose); });
    session.value()->set_keyframe_callback([raw](const msgs::Keyframe& keyframe) {
      for (const auto& subscriber : raw->keyframe_subscribers) subscriber->publish(keyframe);
    });
    return session;
  }

  // Map updates are built only while someone subscribes to them: after a backend correction a
  // full replacement rebuilds the whole point map, which with 20 sessions on two cores cost a
  // sweep in ten. Installs or removes the session's callback; caller holds managed.mutex.
  static void sync_map_updates(ManagedSession& managed) {
    std::erase_if(managed.map_subscribers, [](const auto& subscriber) { return subscriber->closed(); });
    const bool wanted = !managed.map_subscribers.empty() && managed.session;
    if (wanted == managed.map_updates_installed) return;
    if (wanted) {
      ManagedSession* raw = &managed;
      managed.session->set_map_update_callback([raw](const msgs::MapUpdate& update) {
        msgs::MapUpdate with_id = update;
        with_id.map_id = raw->record.id;
        for (const auto& subscriber : raw->map_subscribers) subscriber->publish(with_id);
      });
    } else if (managed.session) {
      managed.session->set_map_update_callback(nullptr);
    }
    managed.map_updates_installed = wanted;
  }

  // The session's map with its metadata; caller holds managed.mutex.
  std::optional<msgs::FusionMap> map_locked(const ManagedSession& managed) const {
    if (!managed.session) return managed.final_map;
    const pipeline::MappingSummary mapping = managed.session->mapping_summary();
    if (mapping.map_keyframes == 0 && mapping.visual_keyframes == 0 && mapping.splat_gaussians == 0) return std::nullopt;
    msgs::FusionMap map = managed.session->map();
    map.map_id = managed.record.id;
    map.created = managed.latest_pose ? managed.latest_pose->timestamp : managed.record.created;
    map.sensor_configuration = managed.record.config_yaml + "\n" + managed.record.calibration_yaml;
    return map;
  }

  // Closes and forgets the subscriptions of an ending session; caller holds managed.mutex.
  static void close_subscribers(ManagedSession& managed) {
    for (const auto& subscriber : managed.pose_subscribers) subscriber->close();
    for (const auto& subscriber : managed.keyframe_subscribers) subscriber->close();
    for (const auto& subscriber : managed.map_subscribers) subscriber->close();
    managed.pose_subscribers.clear();
    managed.keyframe_subscribers.clear();
    managed.map_subscribers.clear();
  }

  void on_pose(ManagedSession& managed, const msgs::PoseEstimate& pose) {
    managed.latest_pose = pose;
    recorder->enqueue(managed.record.id, pose);
    for (const auto& subscriber : managed.pose_subscribers) subscriber->publish(pose);
    managed.poses->increment();
    managed.pose_latency->observe(std::chrono::duration<double>(Clock::now() - managed.push_started).count());
    managed.covariance_trace->set(position_covariance_trace(pose));
    managed.tracking_state->set(static_cast<double>(pose.status.state));
  }

  void attach_metrics(ManagedSession& managed) {
    const MetricLabels labels = {{"session", managed.record.id}};
    managed.poses = &metrics->counter("hanzo_fusion_poses_total", "PoseEstimates emitted", labels);
    managed.pose_latency = &metrics->histogram("hanzo_fusion_pose_latency_seconds",
                                               "From receiving a message to the PoseEstimate it produced",
                                               latency_buckets_seconds(), labels);
    managed.covariance_trace = &metrics->gauge("hanzo_fusion_position_covariance_trace_m2",
                                               "Trace of the latest position covariance", labels);
    managed.tracking_state = &metrics->gauge("hanzo_fusion_tracking_state",
                                             "Latest tracking state (1 initializing, 2 tracking, 3 degraded, 4 lost)", labels);
  }

  // Mirrors the sessions' own counters into the registry (runs at every scrape).
  void collect_metrics() {
    std::vector<std::shared_ptr<ManagedSession>> active;
    {
      std::shared_lock lock(sessions_mutex);
      for (const auto& [id, managed] : sessions) active.push_back(managed);
    }
    std::size_t count = 0;
    for (const auto& managed : active) {
      std::lock_guard lock(managed->mutex);
      if (!managed->session) continue;
      ++count;
      const pipeline::SessionSummary summary = managed->session->summary();
      for (const pipeline::SensorStatistics& sensor : summary.sensors) {
        const MetricLabels labels = {{"session", managed->record.id}, {"sensor", sensor.name}};
        metrics->counter("hanzo_fusion_messages_received_total", "Messages received per sensor", labels)
            .set_total(static_cast<double>(sensor.received));
        metrics->counter("hanzo_fusion_messages_fused_total", "Messages fused per sensor", labels)
            .set_total(static_cast<double>(sensor.fused));
        metrics->gauge("hanzo_fusion_sensor_timed_out", "1 while the sensor is silent for longer than its timeout", labels)
            .set(sensor.timed_out ? 1.0 : 0.0);
        for (const auto& [reason, rejected] : sensor.rejected) {
          MetricLabels with_reason = labels;
          with_reason.emplace_back("reason", std::string(pipeline::to_string(reason)));
          metrics->counter("hanzo_fusion_messages_rejected_total", "Messages rejected per sensor and reason", with_reason)
              .set_total(static_cast<double>(rejected));
        }
      }
      for (const pipeline::SensorHealth& health : managed->session->health()) {
        const MetricLabels labels = {{"session", managed->record.id}, {"sensor", health.sensor}};
        metrics->gauge("hanzo_fusion_sensor_health", "0 ok, 1 degraded, 2 lost (reason: the session status' sensors[].health)", labels)
            .set(static_cast<double>(health.state));
      }
      std::size_t depth = 0;
      uint64_t dropped = 0;
      for (const auto& subscriber : managed->pose_subscribers) {
        depth = std::max(depth, subscriber->depth());
        dropped += subscriber->dropped();
      }
      const MetricLabels labels = {{"session", managed->record.id}};
      if (managed->recording) {  // the privacy audit of the session's recording
        const RecordingInfo recording = managed->recording->info();
        metrics->counter("hanzo_fusion_recorded_messages_total", "Messages written to the session's recording", labels)
            .set_total(static_cast<double>(recording.messages));
        metrics->counter("hanzo_fusion_recorded_images_total", "Recorded images the privacy filter checked", labels)
            .set_total(static_cast<double>(recording.images));
        for (const auto& [kind, regions] : {std::pair<const char*, uint64_t>{"face", recording.faces}, {"licence_plate", recording.licence_plates}}) {
          MetricLabels with_kind = labels;
          with_kind.emplace_back("kind", kind);
          metrics->counter("hanzo_fusion_privacy_redactions_total", "Regions redacted in recorded images", with_kind)
              .set_total(static_cast<double>(regions));
        }
      }
      metrics->gauge("hanzo_fusion_subscriber_queue_depth", "Deepest pose subscriber queue", labels).set(static_cast<double>(depth));
      metrics->counter("hanzo_fusion_subscriber_dropped_total", "Poses dropped for slow subscribers (oldest first)", labels)
          .set_total(static_cast<double>(dropped));
      metrics->counter("hanzo_fusion_keyframes_total", "Keyframes emitted", labels).set_total(static_cast<double>(summary.keyframes));
      const pipeline::MappingSummary mapping = managed->session->mapping_summary();
      metrics->counter("hanzo_fusion_lidar_scans_registered_total", "LiDAR sweeps registered to the local map", labels)
          .set_total(static_cast<double>(mapping.scans_registered));
      metrics->counter("hanzo_fusion_lidar_degenerate_scans_total", "Sweeps whose geometry leaves a direction unconstrained (corridors)", labels)
          .set_total(static_cast<double>(mapping.degenerate_scans));
      metrics->counter("hanzo_fusion_lidar_weather_degraded_scans_total", "Sweeps flagged for rain, fog or dust (fused with less weight)", labels)
          .set_total(static_cast<double>(mapping.weather_degraded_scans));
      for (const auto& [outcome, frames] : {std::pair<const char*, uint64_t>{"tracked", mapping.camera_frames_tracked}, {"lost", mapping.camera_frames_lost}}) {
        MetricLabels with_outcome = labels;
        with_outcome.emplace_back("outcome", outcome);
        metrics->counter("hanzo_fusion_camera_frames_total", "Camera frames by tracking outcome", with_outcome).set_total(static_cast<double>(frames));
      }
      for (const auto& [condition, frames] : {std::pair<const char*, uint64_t>{"dark", mapping.camera_dark_frames},
                                              {"glare", mapping.camera_glare_frames},
                                              {"motion_blur", mapping.camera_motion_blur_frames}}) {
        MetricLabels with_condition = labels;
        with_condition.emplace_back("condition", condition);
        metrics->counter("hanzo_fusion_camera_degraded_images_total", "Camera images too dark, washed out by glare or blurred by motion", with_condition)
            .set_total(static_cast<double>(frames));
      }
      if (!mapping.camera_features.empty()) {
        MetricLabels with_detector = labels;
        with_detector.emplace_back("detector", mapping.camera_features);
        with_detector.emplace_back("matcher", mapping.camera_learned_matcher ? "learned" : "ratio");
        metrics->gauge("hanzo_fusion_camera_feature_seconds", "Mean time of the cameras' feature stage per frame, by detector (learned or classical) and matcher",
                       with_detector)
            .set(mapping.camera_feature_ms / 1000.0);
      }
      metrics->gauge("hanzo_fusion_lidar_registration_seconds", "Time of the latest sweep registration", labels)
          .set(mapping.last_registration_ms / 1000.0);
      metrics->counter("hanzo_fusion_loop_closures_total", "Loop closures added (detected and manual)", labels)
          .set_total(static_cast<double>(mapping.loop_closures + mapping.manual_loop_closures));
      metrics->gauge("hanzo_fusion_backend_correction_m", "How far the backend's latest update moved the latest keyframe", labels)
          .set(mapping.last_correction_m);
      metrics->gauge("hanzo_fusion_map_keyframes", "Keyframes in the map", labels).set(static_cast<double>(mapping.map_keyframes));
      metrics->gauge("hanzo_fusion_map_memory_bytes", "Memory held by the map's layers", labels)
          .set(static_cast<double>(mapping.map_memory_bytes));
    }
    active_sessions_gauge->set(static_cast<double>(count));
  }

  ApiResult<std::shared_ptr<ManagedSession>> find(const Principal& caller, const std::string& id, Permission permission) {
    if (const ApiStatus allowed = authorize(caller, permission); !allowed) return allowed.error();
    std::shared_ptr<ManagedSession> managed;
    {
      std::shared_lock lock(sessions_mutex);
      const auto found = sessions.find(id);
      if (found != sessions.end()) managed = found->second;
    }
    if (!managed && replicated()) {
      auto located = locate(id);
      if (!located) return located.error();
      managed = std::move(located).value();
    }
    if (!managed) return ApiError{ErrorCode::kNotFound, fmt::format("no session '{}'", id), "session_id"};
    if (const ApiStatus allowed = authorize(caller, permission, managed->record.organization); !allowed) return allowed.error();
    return managed;
  }

  // Caller holds managed.mutex.
  SessionInfo info_locked(const ManagedSession& managed) const {
    SessionInfo info;
    info.id = managed.record.id;
    info.organization = managed.record.organization;
    info.name = managed.record.name;
    info.created = managed.record.created;
    info.ended = managed.record.ended;
    info.summary = managed.session ? managed.session->summary() : managed.final_summary;
    info.mapping = managed.session ? managed.session->mapping_summary() : managed.final_mapping;
    if (managed.session) info.health = managed.session->health();
    info.latest_pose = managed.latest_pose;
    const detail::StorageProgress progress = recorder->progress(managed.record.id);
    info.stored_poses = progress.stored;
    info.stored_through = progress.stored_through;
    auto open = [](const auto& subscribers) {
      return static_cast<uint64_t>(std::count_if(subscribers.begin(), subscribers.end(), [](const auto& s) { return !s->closed(); }));
    };
    info.pose_subscribers = open(managed.pose_subscribers);
    info.keyframe_subscribers = open(managed.keyframe_subscribers);
    info.map_subscribers = open(managed.map_subscribers);
    info.config_yaml = managed.record.config_yaml;
    info.calibration_yaml = managed.record.calibration_yaml;
    if (managed.recording) info.recording = managed.recording->info();
    if (!managed.record.ended) info.replica = config.replica.id;
    return info;
  }

  // The recording a create request asks for: none, or started with its privacy redaction.
  ApiResult<std::unique_ptr<SessionRecording>> start_recording(const CreateSessionRequest& request, const std::string& session_id) {
    const RecordingConfig& recording = config.recording;
    if (!request.record.value_or(recording.record_by_default)) {
      if (!request.privacy.empty()) return ApiError{ErrorCode::kInvalidArgument, "privacy: applies to a recording; set record too", "privacy"};
      return std::unique_ptr<SessionRecording>();
    }
    if (recording.directory.empty()) {
      return ApiError{ErrorCode::kInvalidArgument, "record: this server records no sessions (start it with --recordings-dir)", "record"};
    }
    std::optional<privacy::Redaction> redaction = recording.redaction;
    if (request.privacy == "off") {
      if (!recording.allow_unfiltered) {
        return ApiError{ErrorCode::kInvalidArgument, "privacy: this server filters every recorded image (off is not allowed)", "privacy"};
      }
      redaction.reset();
    } else if (!request.privacy.empty()) {
      auto parsed = privacy::parse_redaction(request.privacy);
      if (!parsed) return ApiError{ErrorCode::kInvalidArgument, "privacy: " + parsed.error().message + " or off", "privacy"};
      redaction = *parsed;
    }
    auto started = SessionRecording::start(recording, session_id, redaction);
    if (!started) return ApiError::from(ErrorCode::kInternal, started.error());
    return std::move(started).value();
  }

  // Retention over the finished recordings (those of sessions still recording are kept).
  void apply_retention() {
    if (config.recording.directory.empty()) return;
    std::vector<std::string> active;
    {
      std::shared_lock lock(sessions_mutex);
      for (const auto& [id, managed] : sessions) {
        std::lock_guard session_lock(managed->mutex);
        if (managed->recording && managed->recording->info().active) active.push_back(managed->recording->info().file);
      }
    }
    if (auto outcome = apply_recording_retention(config.recording, active); !outcome) {
      logger()->warn("recording retention: {}", outcome.error().message);
    }
  }

  bool replicated() const { return !config.replica.id.empty(); }

  // A stored session as a ManagedSession: its storage progress and map versions; an active one
  // gets a pipeline: with `resume` (a takeover) its filter starts from the newest stored pose,
  // else afresh.
  Result<std::shared_ptr<ManagedSession>> adopt(SessionRecord record, bool resume) {
    auto managed = std::make_shared<ManagedSession>();
    const std::string where = fmt::format("stored session '{}'", record.id);
    TrajectoryExtent extent;
    HANZO_ASSIGN_OR_RETURN(extent, storage->trajectory_extent(record.id));
    recorder->restore(record.id, {extent.count, extent.last});
    if (!record.ended) {
      HANZO_ASSIGN_OR_RETURN(managed->configuration, with_context(config::parse_fusion_config(record.config_yaml, "config"), where));
      HANZO_ASSIGN_OR_RETURN(managed->calibration, with_context(calib::parse_calibration(record.calibration_yaml, "calibration"), where));
    }
    managed->record = std::move(record);
    if (catalog) {  // the next save of its map continues the stored versions
      if (auto stored = catalog->find(managed->record.organization, managed->record.id); stored && !stored->versions.empty()) {
        managed->stored_map_version = stored->versions.back().version;
      }
    }
    if (managed->record.ended) return managed;
    attach_metrics(*managed);
    HANZO_ASSIGN_OR_RETURN(managed->session, with_context(make_pipeline(*managed, managed->configuration, managed->calibration), where));
    if (resume && extent.last) {  // the filter continues from the newest stored state, in the session's frame
      auto newest = storage->poses(managed->record.id, Timestamp::from_nanoseconds(extent.last->nanoseconds() - 1), 1);
      if (newest && !newest->empty()) {
        managed->session->frontend().resume(newest->front());
        managed->latest_pose = newest->front();
        restore_stored_map(*managed);
      } else {
        logger()->warn("session {}: taken over without its newest stored pose; its poses start a new frame", managed->record.id);
      }
    }
    return managed;
  }

  // A taken-over session's newest stored map into its pipeline (Session::restore_map): the map
  // versions this replica saves hold its keyframes, and the first sweeps here register against
  // it. Without one (no save yet) the map holds only what this replica maps.
  void restore_stored_map(ManagedSession& managed) {
    if (!catalog || managed.stored_map_version == 0) return;
    ApiResult<msgs::FusionMap> stored = catalog->load(managed.record.organization, managed.record.id);
    if (!stored) {
      logger()->warn("session {}: its stored map not read ({}); the map starts at the takeover", managed.record.id, stored.error().message);
      return;
    }
    if (Status restored = managed.session->restore_map(stored.value()); !restored) {
      logger()->warn("session {}: {}; the map starts at the takeover", managed.record.id, restored.error().message);
    }
  }

  // Replicas: the stored session `id` when this replica serves it now (it was free or its lease
  // expired: claimed and restarted here), an ended session (read-only), or kUnavailable naming
  // the replica that serves it.
  ApiResult<std::shared_ptr<ManagedSession>> locate(const std::string& id, bool pull = false) {
    std::lock_guard locating(locate_mutex);  // one takeover at a time: concurrent requests find it adopted
    {
      std::shared_lock lock(sessions_mutex);
      if (auto found = sessions.find(id); found != sessions.end()) return found->second;
    }
    auto records = storage->sessions();
    if (!records) return ApiError::from(ErrorCode::kInternal, records.error());
    auto record = std::find_if(records->begin(), records->end(), [&](const SessionRecord& r) { return r.id == id; });
    if (record == records->end()) return ApiError{ErrorCode::kNotFound, fmt::format("no session '{}'", id), "session_id"};
    if (!record->ended) {
      auto lease = claim(id);
      if (!lease) return lease.error();
      if (lease->owner != config.replica.id && pull && config.replica.request_handover) {
        if (const Status handed = config.replica.request_handover(lease.value()); !handed) {
          logger()->warn("session {}: replica {} did not hand it over: {}", id, lease->owner, handed.error().message);
        }
        lease = claim(id);  // its holder handed the lease to this replica
        if (!lease) return lease.error();
      }
      if (lease->owner != config.replica.id) {
        return ApiError{ErrorCode::kUnavailable, fmt::format("session '{}' is served by replica '{}'", id, lease->owner), "", lease->owner_url};
      }
    }
    const bool active = !record->ended;
    auto managed = adopt(std::move(*record), active);
    if (!managed) {
      if (active) (void)storage->release_session(id, config.replica.id);
      return ApiError::from(ErrorCode::kInternal, managed.error());
    }
    std::unique_lock lock(sessions_mutex);
    auto [it, inserted] = sessions.emplace(id, managed.value());
    if (inserted && active) {
      taken_over_counter->increment();
      logger()->info("session {}: taken over by replica {}", id, config.replica.id);
    }
    return it->second;
  }

  // Whether the storage holds session `id` of the caller's organization.
  bool stored_by(const Principal& caller, const std::string& id) {
    auto records = storage->sessions();
    return records && std::any_of(records->begin(), records->end(),
                                  [&](const SessionRecord& r) { return r.id == id && r.organization == caller.organization; });
  }

  // What the storage says of a session another replica serves.
  SessionInfo stored_info(SessionRecord record) {
    SessionInfo info;
    if (auto extent = storage->trajectory_extent(record.id)) {
      info.stored_poses = extent->count;
      info.stored_through = extent->last;
    }
    if (!record.ended) {
      if (auto lease = storage->session_lease(record.id); lease && *lease) info.replica = lease.value()->owner;
    }
    info.id = record.id;
    info.organization = record.organization;
    info.name = record.name;
    info.created = record.created;
    info.ended = record.ended;
    info.config_yaml = std::move(record.config_yaml);
    info.calibration_yaml = std::move(record.calibration_yaml);
    return info;
  }

  // When a lease taken or renewed at `now` runs out.
  Timestamp lease_end(Timestamp now) const {
    return Timestamp::from_nanoseconds(now.nanoseconds() + std::chrono::duration_cast<std::chrono::nanoseconds>(config.replica.lease).count());
  }

  // Claims the session's lease for this replica when it is free or expired.
  ApiResult<SessionLease> claim(const std::string& id) {
    const Timestamp now = Timestamp::wall_clock_now();
    auto lease = storage->claim_session(id, config.replica.id, config.replica.url, now, lease_end(now));
    if (!lease) return ApiError::from(ErrorCode::kInternal, lease.error());
    return std::move(lease).value();
  }

  // Stops serving a session another replica holds now (no end: it runs on there).
  void drop(const std::string& id) {
    std::shared_ptr<ManagedSession> managed;
    {
      std::unique_lock lock(sessions_mutex);
      auto found = sessions.find(id);
      if (found == sessions.end()) return;
      managed = found->second;
      sessions.erase(found);
    }
    std::lock_guard lock(managed->mutex);
    managed->session.reset();
    close_subscribers(*managed);
    metrics->remove_series("session", id);
    lost_counter->increment();
    logger()->error("session {}: another replica holds its lease (this replica's ran out); this replica stops serving it", id);
  }

  void run_lease_keeper(SessionManager& manager) {
    std::unique_lock lock(keeper_mutex);
    while (!keeper_wake.wait_for(lock, config.replica.lease / 3, [this] { return keeper_stopping; })) {
      lock.unlock();
      if (auto kept = manager.keep_leases(); !kept) logger()->warn("session leases: {}", kept.error().message);
      lock.lock();
    }
  }

  std::size_t active_count_locked(const std::string& organization, bool organization_only) const {
    std::size_t count = 0;
    for (const auto& [id, managed] : sessions) {
      if (managed->record.ended) continue;
      if (!organization_only || managed->record.organization == organization) ++count;
    }
    return count;
  }
};

SessionManager::SessionManager(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

SessionManager::~SessionManager() {
  if (impl_->lease_keeper.joinable()) {
    {
      std::lock_guard lock(impl_->keeper_mutex);
      impl_->keeper_stopping = true;
    }
    impl_->keeper_wake.notify_all();
    impl_->lease_keeper.join();
  }
  if (impl_->map_saver.joinable()) {
    {
      std::lock_guard lock(impl_->saver_mutex);
      impl_->saver_stopping = true;
    }
    impl_->saver_wake.notify_all();
    impl_->map_saver.join();
  }
  if (const Status saved = impl_->save_all_maps(); !saved) logger()->error("maps: at shutdown: {}", saved.error().message);
  if (const Status flushed = impl_->recorder->flush(); !flushed) {
    logger()->error("storage: poses not committed at shutdown: {}", flushed.error().message);
  }
  std::unique_lock lock(impl_->sessions_mutex);
  if (impl_->replicated()) {  // handed over: the other replicas take the sessions over at once
    for (const auto& [id, managed] : impl_->sessions) {
      if (managed->record.ended) continue;
      if (const Status released = impl_->storage->release_session(id, impl_->config.replica.id); !released) {
        logger()->warn("session {}: lease not released: {}", id, released.error().message);
      }
    }
  }
  for (auto& [id, managed] : impl_->sessions) {
    std::lock_guard session_lock(managed->mutex);
    Impl::close_subscribers(*managed);
  }
}

Result<std::unique_ptr<SessionManager>> SessionManager::create(const SessionManagerConfig& config, std::unique_ptr<Storage> storage,
                                                               std::shared_ptr<MetricsRegistry> metrics) {
  auto impl = std::make_unique<Impl>();
  impl->config = config;
  impl->storage = std::move(storage);
  impl->metrics = metrics ? std::move(metrics) : std::make_shared<MetricsRegistry>();
  impl->recorder = std::make_unique<detail::PoseRecorder>(*impl->storage, config.storage_flush_interval,
                                                         config.max_pending_poses, *impl->metrics);
  impl->active_sessions_gauge = &impl->metrics->gauge("hanzo_fusion_active_sessions", "Sessions running");

  if (config.object_store) {
    if (!impl->config.recording.archive) impl->config.recording.archive = config.object_store;
    HANZO_ASSIGN_OR_RETURN(impl->catalog, MapCatalog::open(maps::MapStore(config.object_store, "maps/", config.map_store), *impl->storage));
  } else if (!config.map_directory.empty()) {
    Result<maps::MapStore> store = maps::MapStore::open(config.map_directory, config.map_store);
    if (!store) return store.error();
    HANZO_ASSIGN_OR_RETURN(impl->catalog, MapCatalog::open(std::move(store).value(), *impl->storage));
  }
  impl->taken_over_counter = &impl->metrics->counter("hanzo_fusion_sessions_taken_over_total", "Sessions this replica took over after their lease expired");
  impl->lost_counter = &impl->metrics->counter("hanzo_fusion_sessions_lost_total", "Sessions another replica took from this one");
  if (!impl->replicated()) {  // a single server serves every stored session (replicas: keep_leases below)
    std::vector<SessionRecord> records;
    HANZO_ASSIGN_OR_RETURN(records, impl->storage->sessions());
    for (SessionRecord& record : records) {
      std::shared_ptr<ManagedSession> managed;
      HANZO_ASSIGN_OR_RETURN(managed, impl->adopt(std::move(record), false));
      impl->sessions.emplace(managed->record.id, std::move(managed));
    }
  }
  Impl* raw = impl.get();
  impl->metrics->add_collector([raw] { raw->collect_metrics(); });
  if (impl->catalog && config.map_save_interval.count() > 0) impl->map_saver = std::thread([raw] { raw->run_map_saver(); });
  impl->apply_retention();  // recordings of earlier runs that expired meanwhile
  auto manager = std::unique_ptr<SessionManager>(new SessionManager(std::move(impl)));
  if (raw->replicated()) {
    HANZO_RETURN_IF_ERROR(manager->keep_leases());
    raw->lease_keeper = std::thread([raw, &self = *manager] { raw->run_lease_keeper(self); });
    logger()->info("sessions: replica '{}' ({}) serves {} on {} storage; leases of {} ms", raw->config.replica.id, raw->config.replica.url,
                   raw->active_count_locked("", false), raw->storage->backend(), raw->config.replica.lease.count());
  } else {
    logger()->info("sessions: {} restored from {} storage ({} stored in all)", raw->active_count_locked("", false),
                   raw->storage->backend(), raw->sessions.size());
  }
  return manager;
}

ApiResult<SessionInfo> SessionManager::create_session(const Principal& caller, const CreateSessionRequest& request) {
  if (const ApiStatus allowed = authorize(caller, Permission::kSessionWrite); !allowed) return allowed.error();
  auto managed = std::make_shared<ManagedSession>();
  auto configuration = config::parse_fusion_config(request.config_yaml, "config");
  if (!configuration) return ApiError::from(ErrorCode::kInvalidArgument, configuration.error());  // "config:LINE: ..." already
  managed->configuration = std::move(configuration).value();
  if (!request.calibration_yaml.empty()) {
    auto calibration = calib::parse_calibration(request.calibration_yaml, "calibration");
    if (!calibration) return ApiError::from(ErrorCode::kInvalidArgument, calibration.error());  // "calibration:LINE: ..." already
    managed->calibration = std::move(calibration).value();
  }
  SessionRecord& record = managed->record;
  record.id = generate_session_id();
  record.organization = caller.organization;
  record.name = request.name.empty() ? "session-" + record.id.substr(0, 8) : request.name;
  record.config_yaml = config::to_yaml(managed->configuration);
  record.calibration_yaml = calib::to_yaml(managed->calibration);
  record.created = Timestamp::wall_clock_now();
  auto pipeline = impl_->make_pipeline(*managed, managed->configuration, managed->calibration);
  if (!pipeline) return ApiError{ErrorCode::kInvalidArgument, "config: " + pipeline.error().message, "config"};
  managed->session = std::move(pipeline).value();
  auto recording = impl_->start_recording(request, record.id);
  if (!recording) return recording.error();
  managed->recording = std::move(recording).value();

  std::unique_lock lock(impl_->sessions_mutex);
  if (impl_->active_count_locked("", false) >= impl_->config.max_sessions) {
    return ApiError{ErrorCode::kResourceExhausted, fmt::format("the server runs its maximum of {} sessions", impl_->config.max_sessions), ""};
  }
  if (impl_->active_count_locked(caller.organization, true) >= impl_->config.max_sessions_per_organization) {
    return ApiError{ErrorCode::kResourceExhausted,
                    fmt::format("organization '{}' runs its maximum of {} sessions", caller.organization,
                                impl_->config.max_sessions_per_organization), ""};
  }
  if (const Status stored = impl_->storage->create_session(record); !stored) {
    return ApiError::from(ErrorCode::kInternal, stored.error());
  }
  if (impl_->replicated()) {  // a new id: nobody else can hold it
    auto lease = impl_->claim(record.id);
    if (!lease) return lease.error();
  }
  impl_->attach_metrics(*managed);
  impl_->sessions.emplace(record.id, managed);
  lock.unlock();
  logger()->info("session {} ('{}') created by {}", record.id, record.name, caller.name);
  std::lock_guard session_lock(managed->mutex);
  return impl_->info_locked(*managed);
}

ApiResult<std::vector<SessionInfo>> SessionManager::list_sessions(const Principal& caller) {
  if (const ApiStatus allowed = authorize(caller, Permission::kSessionRead); !allowed) return allowed.error();
  std::vector<std::shared_ptr<ManagedSession>> visible;
  {
    std::shared_lock lock(impl_->sessions_mutex);
    for (const auto& [id, managed] : impl_->sessions) {
      if (managed->record.organization == caller.organization) visible.push_back(managed);
    }
  }
  std::sort(visible.begin(), visible.end(), [](const auto& a, const auto& b) { return a->record.created < b->record.created; });
  std::vector<SessionInfo> infos;
  for (const auto& managed : visible) {
    std::lock_guard lock(managed->mutex);
    infos.push_back(impl_->info_locked(*managed));
  }
  if (impl_->replicated()) {  // what the other replicas serve, as the storage has it
    auto records = impl_->storage->sessions();
    if (!records) return ApiError::from(ErrorCode::kInternal, records.error());
    for (SessionRecord& record : records.value()) {
      if (record.organization != caller.organization) continue;
      if (std::any_of(infos.begin(), infos.end(), [&](const SessionInfo& info) { return info.id == record.id; })) continue;
      infos.push_back(impl_->stored_info(std::move(record)));
    }
    std::sort(infos.begin(), infos.end(), [](const SessionInfo& a, const SessionInfo& b) { return a.created < b.created; });
  }
  return infos;
}

ApiResult<SessionInfo> SessionManager::session_info(const Principal& caller, const std::string& session_id) {
  auto managed = impl_->find(caller, session_id, Permission::kSessionRead);
  if (!managed) return managed.error();
  std::lock_guard lock(managed.value()->mutex);
  return impl_->info_locked(*managed.value());
}

ApiResult<StoredRecording> SessionManager::recording(const Principal& caller, const std::string& session_id) {
  auto managed = impl_->find(caller, session_id, Permission::kSessionRead);
  if (!managed) return managed.error();
  std::unique_lock lock(managed.value()->mutex);
  std::vector<std::string> files;
  if (managed.value()->recording) {
    const RecordingInfo info = managed.value()->recording->info();
    if (info.active) {
      return ApiError{ErrorCode::kConflict, fmt::format("the recording of session '{}' is still being written; end the session first", session_id),
                      ""};
    }
    files.push_back(info.file);
  } else {  // recorded by an earlier run of the server (a session still running then records no more)
    files = {session_id + ".mcap.enc", session_id + ".mcap"};
  }
  lock.unlock();
  Result<StoredRecording> stored = Error("", std::string(object_store::kNotFound));
  for (const std::string& file : files) {
    stored = find_recording(impl_->config.recording, file);
    if (stored || stored.error().field != object_store::kNotFound) break;
  }
  if (!stored) {
    if (stored.error().field == object_store::kNotFound) {
      return ApiError{ErrorCode::kNotFound,
                      fmt::format("session '{}' has no recording: not recorded, or deleted by the retention policy", session_id), ""};
    }
    return ApiError::from(ErrorCode::kInternal, stored.error());
  }
  return std::move(stored).value();
}

ApiResult<SessionInfo> SessionManager::end_session(const Principal& caller, const std::string& session_id) {
  auto found = impl_->find(caller, session_id, Permission::kSessionWrite);
  if (!found) return found.error();
  ManagedSession& managed = *found.value();
  std::unique_lock save_lock(impl_->save_mutex);
  std::unique_lock lock(managed.mutex);
  if (managed.record.ended) return ApiError{ErrorCode::kConflict, fmt::format("session '{}' has already ended", session_id), ""};
  managed.session->flush();
  // The final map is stored (kept in memory only when the server stores no maps).
  if (const ApiStatus saved = impl_->save_map(managed, lock, false); !saved) return saved.error();
  save_lock.unlock();
  const Timestamp ended = Timestamp::wall_clock_now();
  if (const Status stored = impl_->storage->end_session(session_id, ended); !stored) {
    return ApiError::from(ErrorCode::kInternal, stored.error());
  }
  managed.record.ended = ended;
  if (impl_->replicated()) {
    if (const Status released = impl_->storage->release_session(session_id, impl_->config.replica.id); !released) {
      logger()->warn("session {}: lease not released: {}", session_id, released.error().message);
    }
  }
  managed.final_summary = managed.session->summary();
  managed.final_mapping = managed.session->mapping_summary();
  if (!impl_->catalog) managed.final_map = impl_->map_locked(managed);
  managed.session.reset();
  Impl::close_subscribers(managed);
  if (managed.recording) {
    if (const Status finished = managed.recording->finish(); !finished) logger()->error("session {}: recording: {}", session_id, finished.error().message);
  }
  lock.unlock();
  impl_->apply_retention();
  if (const Status flushed = impl_->recorder->flush(); !flushed) return ApiError::from(ErrorCode::kInternal, flushed.error());
  impl_->metrics->remove_series("session", session_id);
  logger()->info("session {} ended by {}", session_id, caller.name);
  lock.lock();
  return impl_->info_locked(managed);
}

ApiResult<SessionInfo> SessionManager::register_sensor(const Principal& caller, const std::string& session_id,
                                                       const SensorRegistration& registration) {
  auto found = impl_->find(caller, session_id, Permission::kSessionWrite);
  if (!found) return found.error();
  ManagedSession& managed = *found.value();
  std::lock_guard lock(managed.mutex);
  if (managed.record.ended) return ApiError{ErrorCode::kConflict, fmt::format("session '{}' has ended", session_id), ""};
  if (managed.configuration.find_sensor(registration.name) != nullptr) {
    return ApiError{ErrorCode::kConflict, fmt::format("sensor '{}' is already registered", registration.name), "name"};
  }
  if (managed.messages_pushed > 0) {
    return ApiError{ErrorCode::kConflict,
                    fmt::format("session '{}' has received data; register sensors before streaming (or create a new session)",
                                session_id), ""};
  }
  auto rebuilt = with_sensor(managed.configuration, managed.calibration, registration);
  if (!rebuilt) return ApiError::from(ErrorCode::kInvalidArgument, rebuilt.error());
  auto& [configuration, calibration] = rebuilt.value();
  auto pipeline = impl_->make_pipeline(managed, configuration, calibration);
  if (!pipeline) return ApiError{ErrorCode::kInvalidArgument, "config: " + pipeline.error().message, "config"};
  const std::string config_yaml = config::to_yaml(configuration);
  const std::string calibration_yaml = calib::to_yaml(calibration);
  if (const Status stored = impl_->storage->update_session_setup(session_id, config_yaml, calibration_yaml); !stored) {
    return ApiError::from(ErrorCode::kInternal, stored.error());
  }
  managed.configuration = std::move(configuration);
  managed.calibration = std::move(calibration);
  managed.record.config_yaml = config_yaml;
  managed.record.calibration_yaml = calibration_yaml;
  managed.session = std::move(pipeline).value();
  managed.map_updates_installed = false;
  Impl::sync_map_updates(managed);  // subscribers of the previous pipeline keep their updates
  return impl_->info_locked(managed);
}

ApiStatus SessionManager::push(const Principal& caller, const std::string& session_id, const std::string& sensor,
                               msgs::SensorMessage message) {
  auto found = impl_->find(caller, session_id, Permission::kSessionWrite);
  if (!found) return found.error();
  ManagedSession& managed = *found.value();
  std::lock_guard lock(managed.mutex);
  if (managed.handed_over) return ApiError{ErrorCode::kUnavailable, fmt::format("session '{}' moved to another replica; reconnect", session_id), ""};
  if (!managed.session) return ApiError{ErrorCode::kConflict, fmt::format("session '{}' has ended", session_id), ""};
  std::string sensor_name = sensor;
  if (sensor_name.empty()) {
    const config::SensorModality modality = config::modality_of(message);
    for (const config::SensorConfig& candidate : managed.configuration.sensors) {
      if (candidate.modality != modality) continue;
      if (!sensor_name.empty()) {
        return ApiError{ErrorCode::kInvalidArgument,
                        fmt::format("session '{}' has several {} sensors; name one", session_id, config::to_string(modality)),
                        "sensor"};
      }
      sensor_name = candidate.name;
    }
    if (sensor_name.empty()) {
      return ApiError{ErrorCode::kInvalidArgument,
                      fmt::format("session '{}' has no {} sensor", session_id, config::to_string(modality)), "sensor"};
    }
  }
  if (managed.map_updates_installed) Impl::sync_map_updates(managed);  // drops it when the last subscriber left
  if (managed.recording) {
    if (const config::SensorConfig* configured = managed.configuration.find_sensor(sensor_name)) {
      // A camera's detections on a channel of their own (what `run` reads back).
      const bool detections = std::holds_alternative<msgs::DetectionsMessage>(message);
      managed.recording->record(detections ? configured->topic + std::string(config::kDetectionsTopicSuffix) : configured->topic, sensor_name, message);
    }
  }
  managed.push_started = Clock::now();
  ++managed.messages_pushed;
  const pipeline::PushStatus pushed = managed.session->push(sensor_name, std::move(message));
  if (!pushed) {
    // A malformed message or a sensor the session does not have is the request's fault (400,
    // field "sensor" or "message"); a well-formed message at the wrong time is refused (422).
    switch (pushed.reason()) {
      case pipeline::Rejection::kUnknownSensor:
        return ApiError{ErrorCode::kInvalidArgument, pushed.error().message, "sensor"};
      case pipeline::Rejection::kWrongType:
      case pipeline::Rejection::kInvalid:
        return ApiError{ErrorCode::kInvalidArgument, pushed.error().message, "message"};
      default:
        return ApiError::from(ErrorCode::kRejected, pushed.error());
    }
  }
  return api_ok();
}

ApiResult<msgs::PoseEstimate> SessionManager::current_pose(const Principal& caller, const std::string& session_id) {
  auto found = impl_->find(caller, session_id, Permission::kSessionRead);
  if (!found) return found.error();
  std::lock_guard lock(found.value()->mutex);
  if (!found.value()->latest_pose) {
    return ApiError{ErrorCode::kNotFound, fmt::format("session '{}' has no pose yet", session_id), ""};
  }
  return *found.value()->latest_pose;
}

ApiResult<TrajectoryPage> SessionManager::trajectory(const Principal& caller, const std::string& session_id, Timestamp after,
                                                     std::size_t limit) {
  auto found = impl_->find(caller, session_id, Permission::kSessionRead);
  if (!found && found.error().served_by.empty()) return found.error();
  if (!found && !impl_->stored_by(caller, session_id)) return found.error();  // served elsewhere: any replica reads the storage
  if (limit == 0 || limit > 100000) {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("limit {} is outside 1..100000", limit), "limit"};
  }
  auto poses = impl_->storage->poses(session_id, after, limit + 1);
  if (!poses) return ApiError::from(ErrorCode::kInternal, poses.error());
  TrajectoryPage page;
  page.poses = std::move(poses).value();
  if (page.poses.size() > limit) {
    page.poses.resize(limit);
    page.next_after = page.poses.back().timestamp;
  }
  return page;
}

ApiResult<std::shared_ptr<PoseSubscription>> SessionManager::subscribe_poses(const Principal& caller, const std::string& session_id) {
  auto found = impl_->find(caller, session_id, Permission::kSessionRead);
  if (!found) return found.error();
  ManagedSession& managed = *found.value();
  std::lock_guard lock(managed.mutex);
  if (!managed.session) return ApiError{ErrorCode::kConflict, fmt::format("session '{}' has ended", session_id), ""};
  return add_subscription(managed.pose_subscribers, impl_->config.subscriber_queue_capacity);
}

ApiResult<std::shared_ptr<KeyframeSubscription>> SessionManager::subscribe_keyframes(const Principal& caller, const std::string& session_id) {
  auto found = impl_->find(caller, session_id, Permission::kSessionRead);
  if (!found) return found.error();
  ManagedSession& managed = *found.value();
  std::lock_guard lock(managed.mutex);
  if (!managed.session) return ApiError{ErrorCode::kConflict, fmt::format("session '{}' has ended", session_id), ""};
  return add_subscription(managed.keyframe_subscribers, impl_->config.subscriber_queue_capacity);
}

ApiResult<std::shared_ptr<MapSubscription>> SessionManager::subscribe_map(const Principal& caller, const std::string& session_id) {
  auto found = impl_->find(caller, session_id, Permission::kMapRead);
  if (!found) return found.error();
  ManagedSession& managed = *found.value();
  std::lock_guard lock(managed.mutex);
  if (!managed.session) return ApiError{ErrorCode::kConflict, fmt::format("session '{}' has ended", session_id), ""};
  // Map updates are large (a full replacement holds the whole point map): a short queue.
  auto subscription = add_subscription(managed.map_subscribers, std::max<std::size_t>(1, impl_->config.subscriber_queue_capacity / 64));
  Impl::sync_map_updates(managed);
  return subscription;
}

ApiResult<msgs::FusionMap> SessionManager::map(const Principal& caller, const std::string& session_id) {
  auto found = impl_->find(caller, session_id, Permission::kMapRead);
  if (!found) return found.error();
  std::optional<msgs::FusionMap> map;
  {
    std::lock_guard lock(found.value()->mutex);
    map = impl_->map_locked(*found.value());
  }
  if (map) return std::move(*map);
  if (impl_->catalog) {  // restored after a restart, or ended: the newest stored version
    if (auto stored = impl_->catalog->load(found.value()->record.organization, session_id); stored) return std::move(stored).value();
  }
  return ApiError{ErrorCode::kNotFound,
                  fmt::format("session '{}' has no map yet (it maps with a 3D LiDAR once the IMU has initialized, or with cameras once their odometry has a keyframe)", session_id), ""};
}

ApiResult<pipeline::LoopClosureOutcome> SessionManager::close_loop(const Principal& caller, const std::string& session_id,
                                                                   const pipeline::LoopClosureRequest& request) {
  auto found = impl_->find(caller, session_id, Permission::kSessionWrite);
  if (!found) return found.error();
  ManagedSession& managed = *found.value();
  std::lock_guard lock(managed.mutex);
  if (!managed.session) return ApiError{ErrorCode::kConflict, fmt::format("session '{}' has ended", session_id), ""};
  Result<pipeline::LoopClosureOutcome> outcome = managed.session->close_loop(request);
  if (!outcome) {
    const std::string& message = outcome.error().message;
    const ErrorCode code = message.starts_with("not_found")      ? ErrorCode::kNotFound
                           : message.starts_with("not_verified") ? ErrorCode::kRejected
                                                                 : ErrorCode::kInvalidArgument;
    return ApiError::from(code, outcome.error());
  }
  return std::move(outcome).value();
}

ApiResult<maps::MapVersionInfo> SessionManager::load_map(const Principal& caller, msgs::FusionMap map, const std::string& name) {
  if (const ApiStatus allowed = impl_->may_use_maps(caller, Permission::kMapWrite); !allowed) return allowed.error();
  ApiResult<maps::MapVersionInfo> saved = impl_->catalog->save(caller.organization, "", name, std::move(map));
  if (saved) logger()->info("map {} version {} loaded by {}", saved->map_id, saved->version, caller.name);
  return saved;
}

ApiResult<std::size_t> SessionManager::delete_map(const Principal& caller, const std::string& map_id, std::optional<uint64_t> version) {
  if (const ApiStatus allowed = impl_->may_use_maps(caller, Permission::kMapWrite); !allowed) return allowed.error();
  if (!version) {
    std::shared_ptr<ManagedSession> live;
    {
      std::shared_lock lock(impl_->sessions_mutex);
      if (const auto found = impl_->sessions.find(map_id); found != impl_->sessions.end()) live = found->second;
    }
    if (live && live->record.organization == caller.organization) {
      std::lock_guard lock(live->mutex);
      if (live->session) {
        return ApiError{ErrorCode::kConflict, fmt::format("map '{}' is the map of a running session: end the session first", map_id), "map_id"};
      }
    }
  }
  ApiResult<std::size_t> deleted = impl_->catalog->remove(caller.organization, map_id, version);
  if (deleted) logger()->info("map {}{} deleted by {}", map_id, version ? fmt::format(" version {}", *version) : "", caller.name);
  return deleted;
}

ApiResult<std::vector<StoredMap>> SessionManager::list_maps(const Principal& caller) {
  if (const ApiStatus allowed = impl_->may_use_maps(caller, Permission::kMapRead); !allowed) return allowed.error();
  return impl_->catalog->list(caller.organization);
}

ApiResult<StoredMap> SessionManager::stored_map_info(const Principal& caller, const std::string& map_id) {
  if (const ApiStatus allowed = impl_->may_use_maps(caller, Permission::kMapRead); !allowed) return allowed.error();
  return impl_->catalog->find(caller.organization, map_id);
}

ApiResult<msgs::FusionMap> SessionManager::stored_map(const Principal& caller, const std::string& map_id, std::optional<uint64_t> version) {
  if (const ApiStatus allowed = impl_->may_use_maps(caller, Permission::kMapRead); !allowed) return allowed.error();
  return impl_->catalog->load(caller.organization, map_id, version);
}

ApiResult<std::pair<uint64_t, std::string>> SessionManager::stored_map_file(const Principal& caller, const std::string& map_id,
                                                                           std::optional<uint64_t> version) {
  if (const ApiStatus allowed = impl_->may_use_maps(caller, Permission::kMapRead); !allowed) return allowed.error();
  return impl_->catalog->file(caller.organization, map_id, version);
}

ApiResult<RelocalizeResult> SessionManager::relocalize(const Principal& caller, const std::string& session_id, const RelocalizeRequest& request) {
  auto found = impl_->find(caller, session_id, Permission::kSessionWrite);
  if (!found) return found.error();
  if (const ApiStatus allowed = impl_->may_use_maps(caller, Permission::kMapRead); !allowed) return allowed.error();
  RelocalizeResult result;
  result.map_id = request.map_id;
  if (request.version) {
    result.version = *request.version;
  } else {
    auto stored = impl_->catalog->find(caller.organization, request.map_id);
    if (!stored) return stored.error();
    if (stored->versions.empty()) return ApiError{ErrorCode::kNotFound, fmt::format("map '{}' has no stored version", request.map_id), "map_id"};
    result.version = stored->versions.back().version;
  }
  ManagedSession& managed = *found.value();
  RelocalizeSensor sensor = request.sensor;
  {
    std::lock_guard lock(managed.mutex);
    if (!managed.session) return ApiError{ErrorCode::kConflict, fmt::format("session '{}' has ended", session_id), ""};
    if (sensor == RelocalizeSensor::kAuto) {
      if (managed.session->maps_lidar_sweeps()) {
        sensor = RelocalizeSensor::kLidar;
      } else if (managed.session->has_camera_odometry()) {
        sensor = RelocalizeSensor::kCamera;
      } else {
        return ApiError{ErrorCode::kInvalidArgument, fmt::format("session '{}' maps no LiDAR and has no camera odometry to relocalize with", session_id), ""};
      }
    }
  }
  // The map's layer for the sensor, prepared outside the session's lock (a LiDAR map's
  // localizer is cached).
  std::shared_ptr<const lidar::MapLocalizer> localizer;
  std::optional<msgs::VisualLandmarkLayer> landmarks;
  if (sensor == RelocalizeSensor::kLidar) {
    auto prepared = impl_->localizer(caller.organization, request.map_id, result.version);
    if (!prepared) return prepared.error();
    localizer = std::move(prepared).value();
  } else {
    ApiResult<msgs::FusionMap> map = impl_->catalog->load(caller.organization, request.map_id, result.version);
    if (!map) return map.error();
    if (!map->visual_landmarks || map->visual_landmarks->positions.empty()) {
      return ApiError{ErrorCode::kInvalidArgument,
                      fmt::format("map '{}' version {} has no visual landmark layer to relocalize a camera in (made by a session with cameras)", request.map_id,
                                  result.version),
                      "map_id"};
    }
    landmarks = std::move(map->visual_landmarks);
  }
  std::lock_guard lock(managed.mutex);
  if (!managed.session) return ApiError{ErrorCode::kConflict, fmt::format("session '{}' has ended", session_id), ""};
  const auto failed = [](const Error& error) {
    const std::string& message = error.message;
    const ErrorCode code = message.starts_with("not_ready")   ? ErrorCode::kConflict
                           : message.starts_with("not_found") ? ErrorCode::kRejected
                                                              : ErrorCode::kInvalidArgument;
    return ApiError::from(code, error);
  };
  if (localizer) {
    Result<pipeline::RelocalizationOutcome> outcome = managed.session->relocalize(*localizer, request.relocalization);
    if (!outcome) return failed(outcome.error());
    result.outcome = std::move(outcome).value();
  } else {
    Result<pipeline::CameraRelocalizationOutcome> outcome = managed.session->relocalize(*landmarks, request.camera);
    if (!outcome) return failed(outcome.error());
    result.camera_outcome = std::move(outcome).value();
  }
  managed.latest_pose = managed.session->frontend().latest_pose();  // already in the map's frame
  logger()->info("session {} relocalized in map {} version {} by {}", session_id, result.map_id, result.version, caller.name);
  return result;
}

Result<std::vector<std::string>> SessionManager::keep_leases() {
  Impl& impl = *impl_;
  std::vector<std::string> taken_over;
  if (!impl.replicated()) return taken_over;
  const Timestamp now = Timestamp::wall_clock_now();
  std::vector<std::string> held;
  HANZO_ASSIGN_OR_RETURN(held, impl.storage->renew_leases(impl.config.replica.id, impl.lease_end(now)));
  std::vector<std::string> local_active;
  {
    std::shared_lock lock(impl.sessions_mutex);
    for (const auto& [id, managed] : impl.sessions) {
      if (!managed->record.ended) local_active.push_back(id);
    }
  }
  for (const std::string& id : local_active) {
    if (std::find(held.begin(), held.end(), id) != held.end()) continue;
    // Not renewed: another replica holds it now (or it was created after the renewal).
    auto lease = impl.storage->session_lease(id);
    if (lease && (!*lease || lease.value()->owner != impl.config.replica.id)) impl.drop(id);
  }
  std::vector<SessionRecord> records;
  HANZO_ASSIGN_OR_RETURN(records, impl.storage->sessions());
  for (const SessionRecord& record : records) {
    if (record.ended) continue;
    {
      std::shared_lock lock(impl.sessions_mutex);
      if (impl.sessions.count(record.id) > 0) continue;
      if (impl.active_count_locked("", false) >= impl.config.max_sessions) break;
    }
    std::optional<SessionLease> lease;
    HANZO_ASSIGN_OR_RETURN(lease, impl.storage->session_lease(record.id));
    // Another replica's lease: left for one more lease period after it expired, so that the
    // replica its clients reconnect to (through the load balancer) claims it on their request
    // and the session restarts once, where its streams arrive.
    if (lease && lease->owner != impl.config.replica.id && impl.lease_end(lease->expires) >= now) continue;
    auto located = impl.locate(record.id);
    if (located && !located.value()->record.ended) taken_over.push_back(record.id);
    else if (!located && located.error().code != ErrorCode::kUnavailable) logger()->warn("session {}: not taken over: {}", record.id, located.error().message);
  }
  return taken_over;
}

ApiStatus SessionManager::serve_here(const Principal& caller, const std::string& session_id) {
  if (!impl_->replicated()) return api_ok();
  {
    std::shared_lock lock(impl_->sessions_mutex);
    if (impl_->sessions.count(session_id) > 0) return api_ok();
  }
  if (!impl_->stored_by(caller, session_id)) return ApiError{ErrorCode::kNotFound, fmt::format("no session '{}'", session_id), "session_id"};
  auto located = impl_->locate(session_id, true);
  if (!located) return located.error();
  return api_ok();
}

ApiStatus SessionManager::hand_over(const std::string& session_id, const std::string& to, const std::string& to_url) {
  Impl& impl = *impl_;
  std::shared_ptr<ManagedSession> managed;
  {
    std::shared_lock lock(impl.sessions_mutex);
    if (auto found = impl.sessions.find(session_id); found != impl.sessions.end()) managed = found->second;
  }
  if (!impl.replicated() || !managed || managed->record.ended) {
    return ApiError{ErrorCode::kNotFound, fmt::format("this replica does not serve session '{}'", session_id), "session_id"};
  }
  {
    std::unique_lock save_lock(impl.save_mutex);
    std::unique_lock lock(managed->mutex);
    if (managed->handed_over || !managed->session) return ApiError{ErrorCode::kNotFound, fmt::format("session '{}' was handed over", session_id), "session_id"};
    managed->session->flush();
    if (const ApiStatus saved = impl.save_map(*managed, lock, false); !saved) return saved.error();
    if (managed->recording) {
      if (const Status finished = managed->recording->finish(); !finished) logger()->error("session {}: recording: {}", session_id, finished.error().message);
    }
    if (const Status flushed = impl.recorder->flush(); !flushed) return ApiError::from(ErrorCode::kInternal, flushed.error());
    Result<bool> transferred = impl.storage->transfer_session(session_id, impl.config.replica.id, to, to_url,
                                                              impl.lease_end(Timestamp::wall_clock_now()));
    if (!transferred) return ApiError::from(ErrorCode::kInternal, transferred.error());
    if (!*transferred) logger()->warn("session {}: another replica held its lease when it was handed over", session_id);
    managed->handed_over = true;
    managed->session.reset();
    Impl::close_subscribers(*managed);
  }
  {
    std::unique_lock lock(impl.sessions_mutex);
    impl.sessions.erase(session_id);
  }
  impl.metrics->remove_series("session", session_id);
  logger()->info("session {}: handed over to replica {}", session_id, to);
  return api_ok();
}

Status SessionManager::save_session_maps() { return impl_->save_all_maps(); }

Status SessionManager::flush_storage() { return impl_->recorder->flush(); }

std::size_t SessionManager::active_sessions() const {
  std::shared_lock lock(impl_->sessions_mutex);
  return impl_->active_count_locked("", false);
}

std::string_view SessionManager::storage_backend() const { return impl_->storage->backend(); }

}  // namespace hanzo::fusion::service
