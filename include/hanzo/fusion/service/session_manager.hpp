#pragma once
// SessionManager: the server's sessions, shared by the REST and gRPC front ends. It owns the
// pipeline::Sessions, decides who may touch them (auth.hpp: organization-scoped permissions),
// persists them (storage.hpp) and feeds subscribers and metrics.
//
//   - create_session: a FusionConfig and a Calibration (YAML text, or JSON which is YAML) become
//     a pipeline::Session, stored with the caller's organization; sessions still active in the
//     storage when the server starts are re-created (their filter starts afresh; the stored
//     trajectory stays).
//   - push: one sensor message into one session (serialized per session); rejections come back
//     as kRejected with the session's reason ("out_of_order: ...") and the session is unchanged.
//   - Every PoseEstimate goes to the latest pose, the pose subscribers (bounded, drop-oldest) and
//     the storage queue, which a writer thread commits in batches (one transaction each,
//     every storage_flush_interval). SessionInfo.stored_poses / stored_through say what is
//     durable: those poses survive kill -9.
//   - Each session is a pipeline::Session: with a 3D LiDAR it also registers sweeps, keeps
//     a keyframe graph, builds a map and closes loops; map(), close_loop(), subscribe_map() and
//     subscribe_keyframes() serve them (an ended session keeps its final map in memory).
//   - Maps (SessionManagerConfig::map_directory or object_store, a MapCatalog): each session's map is saved
//     as a new version of the map whose id is the session id every map_save_interval while it
//     changes and when the session ends (so maps survive restarts, and an ended session's map is
//     read back from the store); clients load maps (load_map: gRPC LoadMap, POST /v1/maps) and
//     read any stored version; relocalize() localizes a session in a stored map
//     (pipeline::Session::relocalize) and moves it into that map's frame.
//   - Recording (session_recording.hpp, SessionManagerConfig::recording): a session created
//     with record (or by the server's default) writes every message pushed into it to a sensor
//     log, images through the privacy filter; the log is finished (and encrypted with the
//     server's key) when the session ends, and the retention policy then runs.
//   - Replicas (SessionManagerConfig::replica, docs/server.md "Replicas"): several servers share
//     one database and object store. Each serves the sessions whose lease (storage.hpp) it
//     holds, renewing them every lease/3. A request for a session another replica serves fails
//     with kUnavailable and ApiError::served_by = that replica's URL (the REST front end
//     forwards it there); trajectories and ended sessions are read from the storage by any
//     replica. A session whose lease expired (its replica died) is claimed by the first replica
//     that needs it (a request for it, or a lease keeper pass one lease period after the expiry)
//     and restarted there: its
//     stored trajectory and map versions stay, and its filter starts from the newest stored pose
//     (Frontend::resume), so its poses continue in the session's frame. A replica that finds another holding a
//     session it served stops serving it. gRPC calls cannot be forwarded: serve_here() moves the
//     session to the replica the load balancer sent them to (the holder hands it over: its poses
//     committed, its map saved, its lease released) and restarts it there as after a takeover.
//   - register_sensor: adds a sensor (configuration entry + calibration entry, validated by the
//     same loaders as the files) before the session has received data; afterwards kConflict.
//
// Thread-safe.

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/service/api_error.hpp"
#include "hanzo/fusion/service/auth.hpp"
#include "hanzo/fusion/service/map_catalog.hpp"
#include "hanzo/fusion/service/metrics.hpp"
#include "hanzo/fusion/service/session_recording.hpp"
#include "hanzo/fusion/service/storage.hpp"
#include "hanzo/fusion/service/subscription.hpp"

namespace hanzo::fusion::service {

/// This server as one of several replicas on one database (docs/server.md "Replicas").
struct ReplicaConfig {
  std::string id;   ///< unique among the replicas; "" runs a single server (every active stored session is restored at start)
  std::string url;  ///< where this replica answers REST ("http://host:port"): other replicas forward its sessions' requests there
  std::chrono::milliseconds lease{10000};  ///< a session lease's length; renewed every lease/3, taken over after it expires
  /// Asks the replica holding `lease` to hand its session over to this one (hand_over() there;
  /// the REST front end's replica_handover_requester). Null: a session another replica serves
  /// stays there.
  std::function<Status(const SessionLease& lease)> request_handover;
};

struct SessionManagerConfig {
  std::size_t max_sessions = 256;                   // active sessions in the server
  std::size_t max_sessions_per_organization = 64;   // active sessions of one organization
  std::chrono::milliseconds storage_flush_interval{20};  // how often queued poses are committed
  std::size_t max_pending_poses = 2'000'000;        // storage queue bound; beyond it poses are dropped (counted)
  std::size_t subscriber_queue_capacity = 1024;     // per subscriber, drop-oldest beyond it
  /// Folder of the stored maps (a maps::MapStore; the server uses DATA_DIR/maps). Empty, and no
  /// object_store: maps are not stored (load_map, stored maps and relocalize answer kUnavailable).
  std::string map_directory;
  /// An object store (an S3 bucket) that keeps the maps (under maps/) instead of map_directory
  /// and the finished recordings (under recordings/, when recording.archive is not set).
  std::shared_ptr<object_store::ObjectStore> object_store;
  /// Stored maps: encryption key (versions saved encrypted) and the keys that decrypt.
  maps::MapStoreConfig map_store;
  /// How often a changed session map is saved as a new version (0: only when the session ends).
  std::chrono::seconds map_save_interval{30};
  /// Retention: the newest versions kept of each session's map (older ones are deleted after
  /// each save; 0 keeps all). Maps clients load are never pruned. A session saving every 30 s
  /// for a day would otherwise keep 2880 versions.
  std::size_t map_keep_versions = 20;
  std::size_t cached_localizers = 4;                // prepared maps kept for relocalize()
  RecordingConfig recording;                         // raw sensor logging of sessions (off without a folder)
  ReplicaConfig replica;                             // one of several replicas (off: id empty)
};

/// Which of the session's sensors places it in the map: the LiDAR's newest sweeps in the map's
/// point layer, or the left camera's newest images in its visual landmark layer. kAuto: the
/// LiDAR when the session maps one, else the cameras.
enum class RelocalizeSensor { kAuto, kLidar, kCamera };

struct RelocalizeRequest {
  std::string map_id;                   // a stored map of the caller's organization
  std::optional<uint64_t> version;      // the latest when empty
  RelocalizeSensor sensor = RelocalizeSensor::kAuto;
  pipeline::RelocalizationRequest relocalization;        // LiDAR
  pipeline::CameraRelocalizationRequest camera;          // cameras
};

struct RelocalizeResult {
  std::string map_id;
  uint64_t version = 0;                 // the stored version localized in
  /// One of the two, by the sensor that placed the session.
  std::optional<pipeline::RelocalizationOutcome> outcome;
  std::optional<pipeline::CameraRelocalizationOutcome> camera_outcome;
};

struct CreateSessionRequest {
  std::string name;              // free text for people; "" gives "session-<id prefix>"
  std::string config_yaml;       // the spec's fusion configuration (`fusion:` document)
  std::string calibration_yaml;  // the spec's calibration (`calibration:` document); "" for none
  std::optional<bool> record = std::nullopt;  // record the raw sensor streams; empty: the server's default
  std::string privacy = "";      // the recording's images: "blur", "black", "off"; "": the server's default
};

struct SensorRegistration {
  std::string name;              // the sensor's name (also its calibration key "<name>_to_body")
  std::string config_yaml;       // its entry under fusion.sensors (modality, topic, rate, ...)
  std::string calibration_yaml;  // its entry in the calibration (rotation, translation, ...); "" for identity
};

struct SessionInfo {
  std::string id;
  std::string organization;
  std::string name;
  Timestamp created;
  std::optional<Timestamp> ended;
  pipeline::SessionSummary summary;          // counts per sensor, state
  pipeline::MappingSummary mapping;          // LiDAR registration, keyframes, loop closures, map
  std::vector<pipeline::SensorHealth> health;  // per sensor, as summary.sensors (empty once ended)
  std::optional<msgs::PoseEstimate> latest_pose;
  uint64_t stored_poses = 0;                 // poses committed to storage (durable)
  std::optional<Timestamp> stored_through;   // timestamp of the newest committed pose
  uint64_t pose_subscribers = 0;             // open SubscribePose / pose streams
  uint64_t keyframe_subscribers = 0;         // open SubscribeKeyframes calls
  uint64_t map_subscribers = 0;              // open SubscribeMap calls
  std::string config_yaml;
  std::string calibration_yaml;
  std::optional<RecordingInfo> recording;    // when the session records (or recorded)
  std::string replica;                       // the replica serving it ("" on a single server or once ended)
};

struct TrajectoryPage {
  std::vector<msgs::PoseEstimate> poses;     // oldest first
  std::optional<Timestamp> next_after;       // pass as `after` for the next page; nullopt at the end
};

using PoseSubscription = Subscription<msgs::PoseEstimate>;
using KeyframeSubscription = Subscription<msgs::Keyframe>;
using MapSubscription = Subscription<msgs::MapUpdate>;

class SessionManager {
 public:
  /// Re-creates the sessions the storage lists as active; fails when one cannot be (its stored
  /// configuration no longer loads), naming it.
  static Result<std::unique_ptr<SessionManager>> create(const SessionManagerConfig& config, std::unique_ptr<Storage> storage,
                                                        std::shared_ptr<MetricsRegistry> metrics);
  ~SessionManager();  // commits what is queued
  SessionManager(const SessionManager&) = delete;
  SessionManager& operator=(const SessionManager&) = delete;

  ApiResult<SessionInfo> create_session(const Principal& caller, const CreateSessionRequest& request);
  /// Active and ended sessions of the caller's organization.
  ApiResult<std::vector<SessionInfo>> list_sessions(const Principal& caller);
  ApiResult<SessionInfo> session_info(const Principal& caller, const std::string& session_id);
  /// Stops the session: subscribers are closed, queued poses committed, the record marked ended
  /// (its trajectory stays readable). Ending an ended session is kConflict.
  ApiResult<SessionInfo> end_session(const Principal& caller, const std::string& session_id);
  ApiResult<SessionInfo> register_sensor(const Principal& caller, const std::string& session_id,
                                         const SensorRegistration& registration);

  /// `sensor` is a configured sensor name; an empty name picks the session's only sensor of the
  /// message's modality (kInvalidArgument when there are several or none).
  /// By value: a sweep moved in reaches the session without a copy.
  ApiStatus push(const Principal& caller, const std::string& session_id, const std::string& sensor,
                 msgs::SensorMessage message);
  ApiResult<msgs::PoseEstimate> current_pose(const Principal& caller, const std::string& session_id);
  /// Stored poses with timestamp > after, at most limit (1..100000).
  ApiResult<TrajectoryPage> trajectory(const Principal& caller, const std::string& session_id, Timestamp after,
                                       std::size_t limit);
  ApiResult<std::shared_ptr<PoseSubscription>> subscribe_poses(const Principal& caller, const std::string& session_id);
  /// Every keyframe the session emits from now on (session:read).
  ApiResult<std::shared_ptr<KeyframeSubscription>> subscribe_keyframes(const Principal& caller, const std::string& session_id);
  /// Map updates from now on (map:read): new keyframe points, full replacements after loop
  /// closures (Session::set_map_update_callback). map_id is the session id.
  ApiResult<std::shared_ptr<MapSubscription>> subscribe_map(const Principal& caller, const std::string& session_id);
  /// The session's map (map:read): map_id = session id, version, created, the session's
  /// configuration and calibration, layers. While the live map has no layer yet (a session
  /// restored after a restart, an ended one) the newest stored version; kNotFound if none.
  ApiResult<msgs::FusionMap> map(const Principal& caller, const std::string& session_id);
  /// A manual loop closure (session:write); kInvalidArgument for a bad request, kNotFound for
  /// unknown keyframes (or keyframes without scans) and a search that found no loop, kRejected
  /// when the registration did not verify the loop, kConflict for an ended session.
  ApiResult<pipeline::LoopClosureOutcome> close_loop(const Principal& caller, const std::string& session_id,
                                                     const pipeline::LoopClosureRequest& request);

  /// Stores a client's map (map:write) as the next version of its map_id (a new UUID when
  /// empty); kPermissionDenied for another organization's map id. `map` must pass
  /// msgs::validate (the front ends decode it with the validating readers).
  ApiResult<maps::MapVersionInfo> load_map(const Principal& caller, msgs::FusionMap map, const std::string& name = "");
  /// Deletes a stored map with every version, or one `version` of it (map:write); returns the
  /// number of versions deleted. kConflict: the map of a running session (end it first), or
  /// `version` is the map's newest; kNotFound: unknown map or version.
  ApiResult<std::size_t> delete_map(const Principal& caller, const std::string& map_id, std::optional<uint64_t> version = std::nullopt);
  /// Stored maps of the caller's organization (map:read), sessions' maps included.
  ApiResult<std::vector<StoredMap>> list_maps(const Principal& caller);
  ApiResult<StoredMap> stored_map_info(const Principal& caller, const std::string& map_id);
  /// The FusionMap file of a stored version (map:read), as stored, with its version.
  ApiResult<std::pair<uint64_t, std::string>> stored_map_file(const Principal& caller, const std::string& map_id,
                                                              std::optional<uint64_t> version = std::nullopt);
  /// A stored version of a map (map:read); the latest when `version` is empty.
  ApiResult<msgs::FusionMap> stored_map(const Principal& caller, const std::string& map_id, std::optional<uint64_t> version = std::nullopt);
  /// Relocalizes a session in a stored map (session:write and map:read). kNotFound: unknown
  /// session, map or version; kInvalidArgument: a bad request or a map without a point layer;
  /// kConflict: an ended session, or one that has no mapped sweep yet; kRejected: no pose in
  /// the map verified (the reason says why). Nothing changes on an error.
  ApiResult<RelocalizeResult> relocalize(const Principal& caller, const std::string& session_id, const RelocalizeRequest& request);
  /// Where a session's finished recording is kept (session:read): its folder or the object
  /// store; kNotFound without one (or once retention deleted it), kConflict while it is still
  /// being written.
  ApiResult<StoredRecording> recording(const Principal& caller, const std::string& session_id);
  /// Saves the maps of the sessions whose map changed since their last save (the saver thread
  /// calls it every map_save_interval; tests call it directly).
  Status save_session_maps();

  /// Blocks until every pose queued so far is committed (or failed); for shutdown and tests.
  Status flush_storage();
  /// Replicas: renews this replica's leases, stops serving sessions another replica took and
  /// takes over the sessions whose lease expired more than one lease period ago (the lease
  /// keeper thread calls it every lease/3; tests call it directly). Returns the sessions taken over. A no-op on a single server.
  Result<std::vector<std::string>> keep_leases();
  /// Replicas: makes this replica serve the session (kOk when it does): free or expired, it is
  /// claimed; held by another live replica, that one is asked to hand it over. kUnavailable
  /// with served_by when it cannot be moved. A no-op on a single server.
  ApiStatus serve_here(const Principal& caller, const std::string& session_id);
  /// Replicas: stops serving a session and hands its lease to replica `to` (at `to_url`), which
  /// serves it from then on: its queued poses committed, its map saved, its recording finished;
  /// its open streams and subscriptions end with kUnavailable (their clients reconnect through
  /// the load balancer). kNotFound when this replica does not serve it.
  ApiStatus hand_over(const std::string& session_id, const std::string& to, const std::string& to_url);

  std::size_t active_sessions() const;
  std::string_view storage_backend() const;

 private:
  struct Impl;
  explicit SessionManager(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace hanzo::fusion::service
