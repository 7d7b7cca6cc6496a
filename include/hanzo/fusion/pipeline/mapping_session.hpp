#pragma once
// MappingSession: a Session with its backend and mapper (the architecture's full pipeline):
// what the server runs per session and what `hanzo-fusion run` can run on a log.
//
//   auto mapping = MappingSession::create(fusion_config, calibration).value();
//   for (...) mapping->push(sensor, message);   // any sensor, as Session::push
//   msgs::FusionMap map = mapping->map();        // points + 2D occupancy of the keyframe scans
//
// Per message:
//  - 3D LiDAR sweeps of the configured LiDAR sensor (the first `lidar` sensor) are checked
//    (msgs::validate, time after the sensor's previous sweep) and wait until the Session's IMU
//    has passed the sweep's end; then LidarInertialOdometry registers the sweep against its
//    local map from the filter's motion and fuses the pose into the Session. When more than
//    max_waiting_scans wait (the IMU stopped), the oldest is dropped ("imu_behind"; "aligning"
//    before the Session's first pose).
//  - Everything else goes to Session::push (same checks, same errors).
//  - Keyframes of the Session (frontend.keyframe_interval) become nodes of a KeyframeGraph
//    (between factors from the filter's relative motion); after each push the graph is updated
//    and corrects the Session. The LiDAR odometry follows the correction (its frame moves with
//    the Session's world).
//  - Map keyframes: the first registered sweep after a Session keyframe, when the LiDAR moved
//    map_keyframe_distance / map_keyframe_angle since the previous map keyframe, is kept
//    (deskewed points, sensor frame) with its pose relative to that Session keyframe. It goes
//    into the map (maps::MapBuilder: point map + 2D occupancy by default) and into the loop
//    closure detector (lidar/loop_closure.hpp: Scan Context + registration). A verified loop
//    adds a between factor under a DCS kernel (KeyframeGraph::add_loop_closure), the graph
//    runs a full batch and corrects the Session, and every map keyframe whose keyframe moved
//    is moved in the map (the point map exactly; occupancy keeps what was integrated).
//  - Manual loop closures (the server's POST /v1/sessions/{id}/loop-closure): close_loop().
//
//  - GNSS fixes the filter fused (Session::set_gnss_callback) become GPS factors on the newest
//    Session keyframe (gnss_factors), their lever arm carried through the body's motion from
//    the keyframe to the fix, so that the graph's corrections agree with GNSS instead of
//    pulling against it (and GNSS bounds the drift of poses a loop closure moves).
//
// Frames: world = the Session's world (ENU when a GNSS datum is known). Units m, s, rad.
// Limits: one 3D LiDAR per session; its clock is the body clock (calibrated time offsets of
// LiDARs are not applied); after a relocalization (world = the map's frame) GNSS fixes are no
// longer added to the graph.
// Not thread-safe: one thread at a time (the server serializes per session).
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
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
#include "hanzo/fusion/pipeline/session.hpp"

namespace hanzo::fusion::pipeline {

struct MappingSessionConfig {
  LidarInertialOdometryConfig lidar_odometry;
  /// The backend; its batch_on_loop_closure is forced on (a loop closure must correct the
  /// map and the Session at once).
  KeyframeGraphConfig backend;
  bool loop_closure = true;
  /// GNSS fixes the filter fused become GPS factors of the keyframe graph.
  bool gnss_factors = true;
  lidar::LoopClosureConfig loop;
  double loop_translation_sigma = 0.05;  ///< m, loop closure factors (detected and manual)
  double loop_rotation_sigma = 0.005;    ///< rad
  double map_keyframe_distance = 1.0;    ///< m of LiDAR motion between map keyframes
  double map_keyframe_angle = 0.2;       ///< rad
  /// Map layers. Default: 0.2 m points (keyframes kept at 0.1 m) and a 0.1 m 2D occupancy grid.
  maps::MapBuilderConfig map = default_map();
  std::size_t max_waiting_scans = 5;     ///< sweeps waiting for the IMU; beyond, the oldest is dropped
  /// Register sweeps on a thread of the session's own (the server's setting): the IMU's poses
  /// never wait for a registration, the result is fused when the next message arrives, as a
  /// measurement in the past (the Session rolls back; it must come within frontend.lag_window_s).
  /// At most two sweeps wait for the worker; push() waits beyond (a sender faster than
  /// registration is slowed down instead of losing sweeps), at most max_registration_wait_s.
  /// Off: sweeps are registered inside
  /// push(), deterministically (replays, tests).
  bool asynchronous_registration = false;
  /// With asynchronous_registration: how long push() waits for the worker when two sweeps
  /// already wait (s); after it the oldest waiting sweep is dropped ("registration_behind").
  /// Empty: wait as long as it takes. The server sets 0: a push() that waited held back every
  /// IMU pose behind it, and the next sweeps then waited for those poses. Applies to live data
  /// only: message times within live_window_s of this machine's clock (sensors stamped by a
  /// synchronized clock); recorded data replayed at any speed always waits (loses no sweep).
  std::optional<double> max_registration_wait_s;
  double live_window_s = 10.0;
  Status validate() const;
  static maps::MapBuilderConfig default_map();
};

/// A manual loop closure between two Session keyframes (ids from the keyframe callback).
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
  uint64_t keyframe_id = 0;      ///< the Session keyframe the correction was applied at
  lidar::MapLocalization localization;
};

struct MappingSummary {
  uint64_t scans_received = 0;
  uint64_t scans_registered = 0;
  uint64_t scans_refused = 0;     ///< refused by the odometry or dropped waiting for the IMU
  uint64_t degenerate_scans = 0;
  uint64_t weather_degraded_scans = 0;
  uint64_t map_keyframes = 0;
  uint64_t graph_keyframes = 0;
  uint64_t loop_candidates = 0;
  uint64_t loop_closures = 0;     ///< detected and verified
  uint64_t manual_loop_closures = 0;
  uint64_t map_version = 0;       ///< increases with every change of the map
  std::size_t map_memory_bytes = 0;
  double last_registration_ms = 0.0;
  double last_correction_m = 0.0; ///< the backend's last correction of the latest keyframe
  uint64_t relocalizations = 0;   ///< successful relocalize() calls
  uint64_t gnss_factors = 0;      ///< GNSS fixes added to the keyframe graph
};

class MappingSession {
 public:
  using KeyframeCallback = std::function<void(const msgs::Keyframe&)>;
  using MapUpdateCallback = std::function<void(const msgs::MapUpdate&)>;

  /// Fails as Session::create does, on an invalid config, or when the LiDAR sensor has no
  /// calibration entry it can read.
  static Result<std::unique_ptr<MappingSession>> create(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                        MappingSessionConfig mapping = {});
  ~MappingSession();
  MappingSession(const MappingSession&) = delete;
  MappingSession& operator=(const MappingSession&) = delete;

  /// One message of the named sensor. Errors as Session::push ("reason: ..."); a LiDAR sweep
  /// is refused with "invalid", "duplicate" or "out_of_order" and otherwise accepted (it may
  /// still fail to register later: counted in mapping_summary and the sensor's statistics).
  /// Taken by value: a sweep moved in is kept without a copy while it waits for the IMU.
  Status push(std::string_view sensor, msgs::SensorMessage message);
  /// Fuses what waits (Session::flush) and registers the sweeps the IMU has passed.
  void flush();
  /// Errors start with the reason: "invalid: ..." (a bad request), "not_found: ..." (unknown
  /// keyframe, keyframe without a scan, no loop found by the search), "not_verified: ..." (the
  /// registration refused the loop: RMSE, overlap, degeneracy). Nothing changes then.
  Result<LoopClosureOutcome> close_loop(const LoopClosureRequest& request);
  /// Localizes the newest map keyframe's sweep (with the two before it) in `map` and moves the
  /// session's world onto the map's frame: poses, keyframes and this session's map come in
  /// the map's frame from then on (a jump of T_map_world, in one Session correction). The
  /// keyframe graph restarts at the next keyframe (anchored there with the filter's
  /// covariance); older map keyframes stay where the relocalization put them and loops to
  /// them are no longer closed. Errors start with the reason: "invalid: ..." (a non-finite
  /// guess or window), "not_ready: ..." (no map keyframe or Session keyframe yet),
  /// "not_found: ..." (the localizer found no pose that verifies; its reason follows).
  /// Nothing changes then.
  Result<RelocalizationOutcome> relocalize(const lidar::MapLocalizer& map, const RelocalizationRequest& request);

  /// The map's layers (points, occupancy) with version = map_version; other metadata empty.
  msgs::FusionMap map() const;
  /// The Session's summary with the LiDAR sensor's counters filled in.
  SessionSummary summary() const;
  MappingSummary mapping_summary() const;
  /// Optimized T_world_body of a Session keyframe known to the graph.
  std::optional<SE3> keyframe_pose(uint64_t keyframe_id) const;

  void set_pose_callback(Session::PoseCallback callback) { session_->set_pose_callback(std::move(callback)); }
  /// Every Session keyframe as emitted.
  void set_keyframe_callback(KeyframeCallback callback) { keyframe_callback_ = std::move(callback); }
  /// New map keyframes (added_points in the world frame) and, after loop closures, the whole
  /// corrected point map (full_replacement).
  void set_map_update_callback(MapUpdateCallback callback) { map_update_callback_ = std::move(callback); }

  Session& session() { return *session_; }
  const Session& session() const { return *session_; }

 private:
  struct MapKeyframe {
    uint64_t anchor = 0;       ///< the Session keyframe
    SE3 T_anchor_lidar;        ///< the sweep's pose relative to the anchor's body
    SE3 T_world_lidar;         ///< where the map has it now
  };
  MappingSession(std::unique_ptr<Session> session, MappingSessionConfig config, std::string lidar_sensor, const SE3& T_body_lidar);
  Status push_scan(msgs::PointCloudMessage scan);
  class RegistrationWorker;
  void register_ready_scans();
  /// Fuses what the worker registered (asynchronous_registration).
  void take_registered();
  void on_registered(Result<LidarInertialOdometry::RegisteredScan> registered);
  void add_map_keyframe(uint64_t anchor, const SE3& T_world_lidar, const std::vector<Eigen::Vector3f>& points);
  /// T_world_lidar of map keyframe k by the graph's current estimate.
  SE3 map_keyframe_pose(std::size_t k) const;
  Status add_loop_factor(uint64_t from, uint64_t to, const SE3& T_from_to, const std::optional<Eigen::Matrix<double, 6, 6>>& covariance);
  /// Runs the backend; moves the map keyframes whose keyframe moved.
  void update_backend();
  /// Moves map keyframes (index -> T_world_lidar) in the map and publishes the corrected map.
  void move_map_keyframes(const std::map<uint64_t, SE3>& moved);
  void count_refused(const std::string& reason);
  /// A fused GNSS fix as a GPS factor on the newest keyframe (gnss_factors).
  void add_gnss_factor(const FusedGnssFix& fix);

  std::unique_ptr<Session> session_;
  MappingSessionConfig config_;
  std::string lidar_sensor_;
  SE3 T_body_lidar_;
  std::unique_ptr<KeyframeGraph> graph_;  ///< replaced by a fresh one at a relocalization
  bool restart_graph_ = false;  ///< the next keyframe starts the graph (after a relocalization)
  std::optional<LidarInertialOdometry> odometry_;
  std::unique_ptr<RegistrationWorker> worker_;  ///< asynchronous_registration
  lidar::LoopClosureDetector loop_closures_;
  maps::MapBuilder map_builder_;
  struct WaitingScan {
    msgs::PointCloudMessage scan;
    Timestamp end;  ///< the latest point time (computed once: checked on every IMU message)
  };
  std::deque<WaitingScan> waiting_scans_;
  std::optional<Timestamp> first_pose_time_;  ///< the Session's first pose seen
  /// How long a sweep may wait for the worker now (max_registration_wait_s for live data).
  std::optional<std::chrono::nanoseconds> registration_wait_limit(Timestamp now_in_data) const;
  std::optional<Timestamp> last_scan_time_;
  std::optional<msgs::Keyframe> latest_keyframe_;   ///< the newest Session keyframe
  SE3 latest_keyframe_uncorrected_;                 ///< its pose before the Session's corrections
  std::vector<MapKeyframe> map_keyframes_;
  std::map<uint64_t, std::size_t> map_keyframe_of_;  ///< Session keyframe id -> map keyframe
  std::optional<uint64_t> last_anchor_;
  double path_ = 0.0;                               ///< m of LiDAR path, registered sweeps
  std::optional<SE3> last_lidar_pose_;
  SensorStatistics lidar_statistics_;
  MappingSummary summary_;
  KeyframeCallback keyframe_callback_;
  MapUpdateCallback map_update_callback_;
};

}  // namespace hanzo::fusion::pipeline
