#include "hanzo/fusion/pipeline/session.hpp"

#include "camera_odometry.hpp"
#include "imu_keyframe_chain.hpp"
#include "lidar_inertial_factors.hpp"
#include "semantic_projection.hpp"
#include "session_splats.hpp"
#include "visual_loop_closures.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <future>
#include <mutex>
#include <thread>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/estimate/attitude_models.hpp"
#include "hanzo/fusion/estimate/static_alignment.hpp"
#include "hanzo/fusion/graph/imu_factors.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/msgs/validate.hpp"
#include "hanzo/fusion/pipeline/camera_detector.hpp"

namespace hanzo::fusion::pipeline {
namespace {

/// The splats of the first camera with intrinsics (fusion.mapping.splats).
Result<std::unique_ptr<SessionSplats>> create_session_splats(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                             const SessionConfig& session, bool maps_3d_lidar) {
  for (const config::SensorConfig& sensor : config.sensors) {
    const calib::SensorCalibration* entry = calibration.find(sensor.name);
    if (sensor.modality != config::SensorModality::kCamera || entry == nullptr || !entry->camera) continue;
    SplatCameraModel camera{sensor.name, entry->camera->intrinsics, entry->camera->distortion, entry->T_body_sensor(), entry->time_offset};
    SessionSplatsConfig splats;
    splats.settings = config.mapping.splats;
    splats.realtime = session.mode == SessionMode::kRealtime;
    splats.threads = session.num_threads;
    splats.seed_from_map = maps_3d_lidar;
    return SessionSplats::create(std::move(camera), splats);
  }
  return Error("mapping.splats: no camera with intrinsics in the calibration");
}

bool configures_gnss(const config::FusionConfig& config) {
  return std::any_of(config.sensors.begin(), config.sensors.end(),
                     [](const config::SensorConfig& sensor) { return sensor.modality == config::SensorModality::kGnss; });
}

// Whether a sensor other than the cameras (and rangefinders, which give the height alone) tells
// the filter how the body moves: without one the camera's odometry is the estimate's only source
// of motion.
bool configures_motion_beside_cameras(const config::FusionConfig& config) {
  return std::any_of(config.sensors.begin(), config.sensors.end(), [](const config::SensorConfig& sensor) {
    return sensor.modality != config::SensorModality::kCamera && sensor.modality != config::SensorModality::kRange;
  });
}

Timestamp sweep_end(const msgs::PointCloudMessage& scan) {
  if (scan.point_timestamps.empty()) return scan.timestamp;
  return *std::max_element(scan.point_timestamps.begin(), scan.point_timestamps.end());
}

// A sweep's times into the body clock (calibration: t_body = t_lidar + offset).
void to_body_clock(msgs::PointCloudMessage& scan, Duration offset) {
  if (offset.nanoseconds() == 0) return;
  scan.timestamp = scan.timestamp + offset;
  for (Timestamp& time : scan.point_timestamps) time = time + offset;
}

// A map keyframe moved this much in the graph is moved in the map.
constexpr double kMapMoveTranslation = 0.01;  // m
constexpr double kMapMoveRotation = 0.001;    // rad
constexpr double kRecentVelocities_s = 2.0;  // s of fused velocities kept for keyframes that come later

}  // namespace

// Registers prepared sweeps on a thread of its own, in order; at most `capacity` wait: beyond,
// submit() blocks (a replay faster than registration slows down instead of losing sweeps), up
// to `max_wait` when given; then it drops the oldest waiting sweep (a live stream must not wait
// long).
class Session::RegistrationWorker {
 public:
  RegistrationWorker(LidarInertialOdometry& odometry, std::size_t capacity)
      : odometry_(odometry), capacity_(capacity), thread_([this] { run(); }) {}
  ~RegistrationWorker() {
    {
      std::lock_guard lock(mutex_);
      stopping_ = true;
    }
    changed_.notify_all();
    thread_.join();
  }
  /// Returns the number of waiting sweeps dropped to make room.
  std::size_t submit(LidarInertialOdometry::PreparedScan scan, std::optional<std::chrono::nanoseconds> max_wait) {
    std::unique_lock lock(mutex_);
    const auto has_room = [&] { return jobs_.size() < capacity_; };
    std::size_t dropped = 0;
    if (!max_wait) {
      changed_.wait(lock, has_room);
    } else if (!changed_.wait_for(lock, *max_wait, has_room)) {
      for (; jobs_.size() >= capacity_; ++dropped) jobs_.pop_front();
    }
    jobs_.push_back(std::move(scan));
    changed_.notify_all();
    return dropped;
  }
  /// The registrations finished so far, in order.
  std::vector<Result<LidarInertialOdometry::RegisteredScan>> take_done() {
    std::lock_guard lock(mutex_);
    std::vector<Result<LidarInertialOdometry::RegisteredScan>> done(std::make_move_iterator(done_.begin()), std::make_move_iterator(done_.end()));
    done_.clear();
    return done;
  }
  void wait_idle() {
    std::unique_lock lock(mutex_);
    changed_.wait(lock, [&] { return jobs_.empty() && !busy_; });
  }

 private:
  void run() {
    std::unique_lock lock(mutex_);
    while (true) {
      changed_.wait(lock, [&] { return stopping_ || !jobs_.empty(); });
      if (stopping_) return;
      LidarInertialOdometry::PreparedScan scan = std::move(jobs_.front());
      jobs_.pop_front();
      busy_ = true;
      changed_.notify_all();  // a slot is free
      lock.unlock();
      Result<LidarInertialOdometry::RegisteredScan> registered = odometry_.register_scan(scan);
      lock.lock();
      done_.push_back(std::move(registered));
      busy_ = false;
      changed_.notify_all();
    }
  }

  LidarInertialOdometry& odometry_;
  std::size_t capacity_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<LidarInertialOdometry::PreparedScan> jobs_;
  std::deque<Result<LidarInertialOdometry::RegisteredScan>> done_;
  bool busy_ = false;
  bool stopping_ = false;
  std::thread thread_;  // last: starts once the members above exist
};

std::string_view to_string(SessionMode mode) { return mode == SessionMode::kRealtime ? "realtime" : "replay"; }

maps::MapBuilderConfig SessionConfig::default_map() {
  maps::MapBuilderConfig map;
  map.occupancy_2d_config.resolution = 0.1;
  map.point_map.voxel_size = 0.2;
  map.point_map.keyframe_voxel_size = 0.1;
  return map;
}

SessionConfig SessionConfig::from(const config::FusionConfig& config) {
  const config::MappingConfig& mapping = config.mapping;
  SessionConfig session;
  session.mapping = mapping.enabled;
  lidar::LidarOdometryConfig& odometry = session.lidar_odometry.odometry;
  odometry.map.voxel_size = mapping.lidar_voxel;
  odometry.registration.max_neighbour_distance = mapping.lidar_voxel;
  odometry.source_voxel_size = mapping.lidar_source_voxel;
  odometry.max_range = mapping.lidar_max_range;
  odometry.map.max_distance = mapping.lidar_max_range;
  session.map.point_map.voxel_size = mapping.map_voxel;
  session.map.point_map.keyframe_voxel_size = std::min(session.map.point_map.keyframe_voxel_size, mapping.map_voxel);
  session.map.occupancy_2d_config.resolution = mapping.occupancy_resolution;
  session.map_keyframe_distance = mapping.keyframe_distance;
  session.map_keyframe_angle = mapping.keyframe_angle;
  session.map.point_map.moving_points.enabled = mapping.remove_moving_points;
  session.loop_closure = mapping.loop_closure;
  session.planar_laser.slam.loop_closure = mapping.loop_closure;
  session.loop.min_travel = mapping.loop_min_travel;
  session.loop.min_search_radius = mapping.loop_search_radius;
  session.loop.max_rmse = mapping.loop_max_rmse;
  session.gnss_factors = mapping.gnss_factors;
  session.backend.gnss_error_correlation_s = mapping.gnss_error_correlation;
  session.velocity_factors = mapping.velocity_factors;
  session.frontend_follows_graph = mapping.follow_graph;
  session.visual_inertial_window_keyframes = mapping.visual_inertial_window;
  return session;
}

Status SessionConfig::validate() const {
  HANZO_RETURN_IF_ERROR(with_context(lidar_odometry.odometry.validate(), "lidar_odometry"));
  HANZO_RETURN_IF_ERROR(with_context(loop.validate(), "loop"));
  if (!(follow_batch_interval_s >= 0)) return Error(fmt::format("follow_batch_interval_s: {} is not >= 0", follow_batch_interval_s));
  HANZO_RETURN_IF_ERROR(with_context(planar_laser.validate(), "planar_laser"));
  HANZO_RETURN_IF_ERROR(with_context(lidar_merge.validate(), "lidar_merge"));
  if (visual_inertial_window_keyframes < 0) return Error(fmt::format("visual_inertial_window_keyframes: {} is not >= 0", visual_inertial_window_keyframes));
  HANZO_RETURN_IF_ERROR(with_context(map.validate(), "map"));
  if (!(loop_translation_sigma > 0) || !(loop_rotation_sigma > 0)) return Error("loop_translation_sigma, loop_rotation_sigma: must be > 0");
  if (!(map_keyframe_distance >= 0) || !(map_keyframe_angle >= 0)) return Error("map_keyframe_distance, map_keyframe_angle: must be >= 0");
  if (max_waiting_scans == 0) return Error("max_waiting_scans: must be > 0");
  if (!(live_window_s > 0)) return Error(fmt::format("live_window_s: {} is not > 0", live_window_s));
  if (!(wheel_slip.window_s > 0) || !(wheel_slip.recovery_s >= 0) || !(wheel_slip.absolute_tolerance_m >= 0) ||
      !(wheel_slip.relative_tolerance >= 0)) {
    return Error("wheel_slip: window_s must be > 0 and the tolerances and recovery_s >= 0");
  }
  return ok_status();
}

Result<std::unique_ptr<Session>> Session::create(const config::FusionConfig& config, const calib::Calibration& calibration) {
  return create(config, calibration, SessionConfig::from(config));
}

Result<std::unique_ptr<Session>> Session::create(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                 SessionConfig session_config) {
  session_config.lidar_odometry.odometry.num_threads = session_config.num_threads;
  // With GNSS the LiDAR map's pose in the world is observable and wanted (lidar_inertial_odometry.hpp).
  if (configures_gnss(config)) session_config.lidar_odometry.estimate_map_frame = true;
  HANZO_RETURN_IF_ERROR(with_context(session_config.validate(), "session config"));
  std::unique_ptr<Frontend> frontend;
  HANZO_ASSIGN_OR_RETURN(frontend, Frontend::create(config, calibration));
  std::string lidar_sensor, wheel_sensor;
  bool planar_laser = false;
  calib::SensorCalibration lidar_calibration, wheel_calibration;
  for (const config::SensorConfig& sensor : config.sensors) {
    const calib::SensorCalibration* entry = calibration.find(sensor.name);
    if (sensor.modality == config::SensorModality::kLidar && lidar_sensor.empty() && session_config.mapping) {
      lidar_sensor = sensor.name;
      planar_laser = sensor.type == config::kPlanarLaserType;
      if (entry != nullptr) lidar_calibration = *entry;
    }
    if (sensor.modality == config::SensorModality::kWheelOdometry && wheel_sensor.empty()) {
      wheel_sensor = sensor.name;
      if (entry != nullptr) wheel_calibration = *entry;
    }
  }
  if (lidar_sensor.empty()) wheel_sensor.clear();  // nothing to check the wheels against
  session_config.backend.batch_on_loop_closure = true;
  // Replay: every optimization inside push(), in order.
  if (session_config.mode == SessionMode::kReplay) session_config.backend.smoother.background_batch = false;
  // GPS factors hold fixes the filter fused, IMU and landmark factors (visual_inertial_factors)
  // the measurements the visual-inertial odometry fused: the graph corrects the filter at loop
  // closures only. (Measured on six simulated flights and walks: moving the filter onto the
  // visual-inertial graph's newest keyframe after every update doubled its error or worse.)
  const bool visual_inertial_graph = session_config.visual_inertial_factors && config.frontend.type == config::FrontendType::kMsckf;
  const auto imu = std::find_if(config.sensors.begin(), config.sensors.end(),
                                [](const config::SensorConfig& sensor) { return sensor.modality == config::SensorModality::kImu; });
  const bool lidar_inertial_graph =
      session_config.lidar_inertial_factors && !visual_inertial_graph && !lidar_sensor.empty() && !planar_laser && imu != config.sensors.end();
  if ((session_config.gnss_factors && configures_gnss(config)) || visual_inertial_graph || lidar_inertial_graph) {
    session_config.backend.correct_on_loop_closures_only = true;
  }
  // The fixes' correlated error is told apart from the motion by an odometry of the world
  // (a 3D LiDAR or a camera). Without one the keyframes' relative motions are the filter's dead
  // reckoning between the fixes it fused, and the graph takes the fixes as independent
  // (measured: the simulated outage drive, IMU + GNSS + wheels, 0.43 m optimized that way,
  // 0.58 m with the error modelled).
  const bool sees_the_world = (!lidar_sensor.empty() && !planar_laser) ||
                              std::any_of(config.sensors.begin(), config.sensors.end(),
                                          [](const config::SensorConfig& sensor) { return sensor.modality == config::SensorModality::kCamera; });
  if (!sees_the_world) session_config.backend.gnss_error_correlation_s = 0.0;
  // Correlated fixes weigh as few: the Frontend's first position (a copy of the first fix) would
  // then hold the graph's world. The fixes give it.
  const bool gnss_error_in_graph =
      session_config.gnss_factors && configures_gnss(config) && session_config.backend.gnss_error_correlation_s > 0.0;
  if (gnss_error_in_graph) session_config.backend.first_position_sigma = 100.0;
  // A LiDAR-inertial graph with the fixes and their error holds the world: the fixes go to it
  // alone and the Frontend follows it after every update (follows_graph).
  const bool follows_graph = session_config.frontend_follows_graph && lidar_inertial_graph && gnss_error_in_graph;
  if (follows_graph) {
    session_config.backend.correct_on_loop_closures_only = false;
    if (session_config.mode == SessionMode::kReplay) session_config.backend.batch_interval_s = session_config.follow_batch_interval_s;
  }
  // With an IMU the keyframes' roll and pitch are measured (gravity); the visual- and
  // LiDAR-inertial graphs have their own IMU factors.
  session_config.backend.level_from_keyframes = !visual_inertial_graph && !lidar_inertial_graph && imu != config.sensors.end();
  // The visual-inertial graph's smoother. Landmarks make it far less linear than a pose graph:
  // Levenberg-Marquardt starts from Ceres' default trust region (the pose graphs' 1e8, nearly
  // Gauss-Newton, had every step of some updates rejected on the simulated walks, leaving the
  // graph stuck). Each keyframe brings X, V, B and up to 60 landmarks: the window of recent
  // variables must span several keyframes (the pose-graph default, 50, is less than one here;
  // walks started in motion diverged with 50 and 200). Two factor hops (keyframe -> landmark ->
  // the keyframes that saw it) reach what a new keyframe moves; a third (all those keyframes'
  // landmarks) cost a quarter of the run and changed no estimate. A loop closure's batch
  // re-optimizes every landmark: at most one every 10 s of keyframes (a drone over the same
  // figure eights for 160 s closed 72 loops, and their batches took 40 % of the run).
  if (visual_inertial_graph) {
    session_config.backend.smoother.batch.initial_trust_region_radius = 1e4;
    session_config.backend.smoother.recent_variables = std::max(session_config.backend.smoother.recent_variables, 400);
    session_config.backend.smoother.neighbour_hops = std::min(session_config.backend.smoother.neighbour_hops, 2);
    session_config.backend.loop_batch_interval_s = std::max(session_config.backend.loop_batch_interval_s, 10.0);
    session_config.backend.window_keyframes = session_config.visual_inertial_window_keyframes;
  }
  // Live, each sensor streams on its own: one may lag another by up to the lag window.
  if (session_config.mode == SessionMode::kRealtime) frontend->set_timeout_grace(config.frontend.lag_window_s);
  std::unique_ptr<CameraOdometry> camera_odometry;
  if (session_config.mapping) HANZO_ASSIGN_OR_RETURN(camera_odometry, CameraOdometry::create(config, calibration));
  auto session = std::unique_ptr<Session>(new Session(std::move(frontend), std::move(session_config), std::move(lidar_sensor), planar_laser,
                                                      lidar_calibration, std::move(wheel_sensor), wheel_calibration));
  session->camera_odometry_ = std::move(camera_odometry);
  session->backend_thread_ = session->config_.backend_thread && visual_inertial_graph && session->config_.mapping;
  if (follows_graph) {
    session->follows_graph_ = true;
    session->frontend_->set_gnss_positions_to_backend(true);
  }
  if (config.mapping.splats.enabled && session->config_.mapping) {
    HANZO_ASSIGN_OR_RETURN(session->splats_, create_session_splats(config, calibration, session->config_, session->odometry_.has_value()));
  }
  if (lidar_inertial_graph) {
    const calib::SensorCalibration* entry = calibration.find(imu->name);
    const calib::SensorCalibration imu_calibration = entry != nullptr ? *entry : calib::SensorCalibration{};
    const ImuChainNoise noise = imu_chain_noise(config, *imu);
    session->lidar_factors_ = std::make_unique<LidarInertialFactors>(session->T_body_lidar_, noise.preintegration, noise.accel_bias_random_walk,
                                                                     noise.gyro_bias_random_walk);
    session->body_imu_ = std::make_unique<BodyImu>(imu_calibration.T_body_sensor(), imu_calibration.time_offset);
    session->imu_sensor_ = imu->name;
  }
  // Cameras with a lens model label the 3D LiDAR's map points with a vision pipeline's output.
  if (session->odometry_) {
    std::vector<SemanticProjection::Camera> cameras;
    for (const config::SensorConfig& sensor : config.sensors) {
      const calib::SensorCalibration* entry = calibration.find(sensor.name);
      if (sensor.modality != config::SensorModality::kCamera || entry == nullptr || !entry->camera || entry->camera->intrinsics.width == 0) continue;
      cameras.push_back({sensor.name, entry->camera->pinhole_camera(), entry->T_body_sensor(), entry->time_offset,
                         cv::Size(static_cast<int>(entry->camera->intrinsics.width), static_cast<int>(entry->camera->intrinsics.height))});
    }
    if (!cameras.empty()) {
      session->semantic_projection_ = std::make_unique<SemanticProjection>(std::move(cameras), session->T_body_lidar_, config.vision.dynamic_objects);
    }
  }
  if (config.vision.detector.enabled() && (session->camera_odometry_ || session->semantic_projection_)) {
    HANZO_ASSIGN_OR_RETURN(session->detector_, CameraDetector::make(config.vision.detector, "fusion.vision.detector"));
    logger()->info("session: object detector {} ({}) on the cameras without a vision pipeline's output", config.vision.detector.type,
                   session->detector_->model_path());
  }
  // Every further 3D LiDAR joins the first one's sweeps.
  if (session->odometry_) {
    std::vector<LidarSweepMerger::Secondary> secondaries;
    for (const config::SensorConfig& sensor : config.sensors) {
      if (sensor.modality != config::SensorModality::kLidar || sensor.name == session->lidar_sensor_ || sensor.type == config::kPlanarLaserType) continue;
      const calib::SensorCalibration* entry = calibration.find(sensor.name);
      const calib::SensorCalibration calibrated = entry != nullptr ? *entry : calib::SensorCalibration{};
      secondaries.push_back({sensor.name, session->T_body_lidar_.inverse() * calibrated.T_body_sensor()});
      session->secondary_lidars_.push_back({calibrated.time_offset, std::nullopt, {}});
    }
    if (!secondaries.empty()) {
      LidarSweepMergerConfig merge = session->config_.lidar_merge;
      merge.min_range = session->config_.lidar_odometry.odometry.min_range;
      merge.max_range = session->config_.lidar_odometry.odometry.max_range;
      session->merger_.emplace(std::move(secondaries), merge);
    }
  }
  if (session->camera_odometry_ && session->camera_odometry_->visual_inertial() && session->config_.loop_closure) {
    // Places of each rig's left camera, loops between views of one rig.
    for (const CameraOdometry::Rig& rig : session->camera_odometry_->rigs()) {
      Result<vision::VisualLoopDetector> detector = vision::VisualLoopDetector::create(rig.left_camera);
      if (!detector) {
        logger()->warn("session: visual loop closure off: {}", detector.error().message);
        session->visual_loops_.clear();
        break;
      }
      session->visual_loops_.push_back(std::make_unique<VisualLoopClosures>(std::move(detector).value(), rig.T_body_left,
                                                                            session->config_.map_keyframe_distance, session->config_.map_keyframe_angle));
    }
  }
  return session;
}

Session::Session(std::unique_ptr<Frontend> frontend, SessionConfig config, std::string lidar_sensor, bool planar_laser,
                 const calib::SensorCalibration& lidar_calibration, std::string wheel_sensor,
                 const calib::SensorCalibration& wheel_calibration)
    : frontend_(std::move(frontend)),
      config_(std::move(config)),
      lidar_sensor_(std::move(lidar_sensor)),
      T_body_lidar_(lidar_calibration.T_body_sensor()),
      lidar_time_offset_(lidar_calibration.time_offset),
      wheel_sensor_(std::move(wheel_sensor)),
      T_body_wheels_(wheel_calibration.T_body_sensor()),
      wheel_time_offset_(wheel_calibration.time_offset),
      slip_monitor_(config_.wheel_slip),
      graph_(std::make_unique<KeyframeGraph>(config_.backend)),
      loop_closures_(config_.loop, config_.lidar_odometry.odometry),
      map_builder_(maps::MapBuilder::create(config_.map).value()) {
  if (planar_laser) {
    // A loop closure's jump moves the Frontend through its newest keyframe (as the graph does).
    planar_.emplace(*frontend_, lidar_sensor_, T_body_lidar_, lidar_time_offset_, config_.planar_laser, [this](const SE3& T_correction) {
      if (!latest_keyframe_) return;
      const SE3 believed = frontend_->world_correction() * latest_keyframe_uncorrected_;
      if (Status moved = frontend_->apply_correction(latest_keyframe_->keyframe_id, T_correction * believed); !moved) {
        logger()->warn("session: the planar laser's loop closure did not move the filter: {}", moved.error().message);
      }
    });
  } else if (!lidar_sensor_.empty()) {
    odometry_.emplace(*frontend_, lidar_sensor_, T_body_lidar_, config_.lidar_odometry, lidar_time_offset_);
    // Two sweeps in the worker's queue: the IMU may then run ~0.3 s ahead of the sweep being
    // registered, inside the default 0.5 s lag window its late pose must land in.
    constexpr std::size_t kWorkerQueue = 2;
    // Without an IMU nothing carries the estimate while a registration runs: sweeps are
    // registered inside push() in both modes.
    if (config_.mode == SessionMode::kRealtime && frontend_->has_imu()) {
      worker_ = std::make_unique<RegistrationWorker>(*odometry_, kWorkerQueue);
    }
  }
  frontend_->set_pose_callback([this](const msgs::PoseEstimate& pose) {
    if (config_.keep_trajectory && (uncorrected_poses_.empty() || uncorrected_poses_.back().timestamp < pose.timestamp)) {
      uncorrected_poses_.push_back({pose.timestamp, frontend_->world_correction().inverse() * pose.T_world_body.to_se3()});
    }
    if (!pose_callback_) return;
    // Each sensor's health as last evaluated (track_health: every 0.2 s of data).
    msgs::PoseEstimate with_health = pose;
    with_health.status.sensor_health.reserve(last_health_.size());
    for (const SensorHealth& health : last_health_) with_health.status.sensor_health.push_back({health.sensor, health.state, health.reason});
    pose_callback_(with_health);
  });
  frontend_->set_keyframe_callback([this](const msgs::Keyframe& emitted) {
    if (!config_.mapping) {
      if (keyframe_callback_) keyframe_callback_(emitted);
      return;
    }
    graph();  // a running backend update finishes and its result applies before the factors change
    msgs::Keyframe keyframe = emitted;
    if (restart_graph_) {  // the first keyframe of a new graph: anchored by its own covariance
      keyframe.T_previous_current.reset();
      keyframe.relative_covariance.reset();
      restart_graph_ = false;
    }
    // In the graph's world (it moves away from the Frontend's between loop closures).
    const auto in_graph_world = [this](const msgs::Keyframe& emitted_keyframe) {
      msgs::Keyframe in_graph = emitted_keyframe;
      const SE3 T_world_body = graph().initial_pose(emitted_keyframe);
      in_graph.velocity = T_world_body.rotation() * (emitted_keyframe.T_world_body.to_se3().rotation().inverse() * emitted_keyframe.velocity);
      in_graph.T_world_body = msgs::Pose::from_se3(T_world_body);
      return in_graph;
    };
    const bool chain_starts = keyframe.keyframe_id == 0 || !keyframe.T_previous_current;
    // Visual-inertial: the IMU and landmark factors; LiDAR-inertial: the IMU and LiDAR factors.
    std::optional<VisualInertialFactors::KeyframeFactors> inertial;
    std::optional<LidarInertialFactors::KeyframeFactors> lidar_inertial;
    VisualInertialFactors* factors = camera_odometry_ && config_.visual_inertial_factors ? camera_odometry_->keyframe_factors() : nullptr;
    if (factors != nullptr) {
      if (chain_starts) factors->restart();
      if (const std::optional<graph::ImuBias> bias = camera_odometry_->imu_bias_body()) {
        inertial = factors->keyframe(in_graph_world(keyframe), *bias, graph().smoother().estimate());
      }
    } else if (lidar_factors_) {
      if (chain_starts) lidar_factors_->restart();
      graph::ImuBias bias;
      if (const auto filter_bias = frontend_->imu_bias()) {
        bias.accelerometer = body_imu_->T_body_imu().rotation() * filter_bias->first;
        bias.gyroscope = body_imu_->T_body_imu().rotation() * filter_bias->second;
      }
      lidar_inertial = lidar_factors_->keyframe(in_graph_world(keyframe), bias, graph().smoother().estimate());
    }
    // Linked by the IMU (and the LiDAR), the filter's relative motion stays as a weak anchor only.
    double relative_scale = 1.0;
    if (inertial && inertial->imu_factor) relative_scale = VisualInertialFactorsConfig{}.odometry_covariance_scale;
    if (lidar_inertial && lidar_inertial->imu_factor && lidar_inertial->lidar_factor) relative_scale = lidar_factors_->config().odometry_covariance_scale;
    if (Status added = graph().add_keyframe(keyframe, relative_scale); !added) {
      logger()->warn("session: keyframe {} not added to the graph: {}", keyframe.keyframe_id, added.error().message);
      // Its factors are dropped: the next keyframe starts new chains.
      if (factors != nullptr) factors->restart();
      if (lidar_factors_) lidar_factors_->restart();
      return;
    }
    if (lidar_inertial) {
      graph().add_factors(lidar_inertial->update);
      summary_.graph_lidar_factors += lidar_inertial->lidar_factor ? 1 : 0;
      summary_.graph_imu_factors += lidar_inertial->imu_factor ? 1 : 0;
    }
    if (inertial) {
      graph().add_factors(inertial->update);
      summary_.graph_landmarks += static_cast<uint64_t>(inertial->new_landmarks);
      summary_.graph_projections += static_cast<uint64_t>(inertial->projections);
    }
    latest_keyframe_ = emitted;
    latest_keyframe_uncorrected_ = frontend_->world_correction().inverse() * emitted.T_world_body.to_se3();
    attach_recent_velocities();
    if (config_.keep_trajectory) {
      keyframe_records_.push_back({emitted.keyframe_id, emitted.timestamp, latest_keyframe_uncorrected_, frontend_->world_correction()});
    }
    ++summary_.graph_keyframes;
    if (keyframe_callback_) keyframe_callback_(emitted);
  });
  frontend_->set_gnss_callback([this](const FusedGnssFix& fix) { add_gnss_factor(fix); });
  frontend_->set_velocity_callback([this](const FusedVelocity& velocity) { add_velocity_factor(velocity); });
  frontend_->set_innovation_callback([this](const InnovationRecord& record) {
    last_update_applied_[record.sensor] = record.applied;
    if (innovation_callback_) innovation_callback_(record);
  });
}

void Session::add_gnss_factor(const FusedGnssFix& fix) {
  if (!config_.gnss_factors || !latest_keyframe_ || restart_graph_ || summary_.relocalizations > 0) return;
  // Both poses before the Frontend's corrections, where their relative motion is the filter's.
  const SE3 T_keyframe_fix = latest_keyframe_uncorrected_.inverse() * (fix.world_correction.inverse() * fix.T_world_body);
  const Status added = graph().add_gps_at_keyframe(latest_keyframe_->keyframe_id, fix.antenna_world, fix.covariance, T_keyframe_fix * fix.lever_arm,
                                                    (fix.timestamp - latest_keyframe_->timestamp).seconds());
  if (!added) {
    logger()->debug("session: GNSS fix at {:.3f} s not added to the graph: {}", fix.timestamp.seconds(), added.error().message);
    return;
  }
  ++summary_.gnss_factors;
}

void Session::add_velocity_factor(const FusedVelocity& velocity) {
  if (!config_.velocity_factors) return;
  recent_velocities_.push_back(velocity);
  // Keyframes reach the Session once final, a moment after their time.
  while ((velocity.timestamp - recent_velocities_.front().timestamp).seconds() > kRecentVelocities_s) recent_velocities_.pop_front();
  attach_recent_velocities();
}

void Session::attach_recent_velocities() {
  if (!latest_keyframe_ || restart_graph_) return;
  const uint64_t keyframe = latest_keyframe_->keyframe_id;
  if (!graph().has_variable(graph::V(keyframe))) return;  // a graph without keyframe velocities
  // Per sensor the velocity nearest to the keyframe in time, once per keyframe.
  std::map<std::string, const FusedVelocity*> nearest;
  const auto offset = [&](const FusedVelocity& velocity) { return std::abs((velocity.timestamp - latest_keyframe_->timestamp).seconds()); };
  for (const FusedVelocity& velocity : recent_velocities_) {
    if (offset(velocity) > config_.velocity_max_time_offset_s) continue;
    const FusedVelocity*& best = nearest[velocity.sensor];
    if (best == nullptr || offset(velocity) < offset(*best)) best = &velocity;
  }
  for (const auto& [sensor, velocity] : nearest) {
    auto [attached, first] = velocity_keyframe_.try_emplace(sensor, keyframe);
    if (!first && attached->second == keyframe) continue;
    attached->second = keyframe;
    const double change = config_.velocity_acceleration_sigma * offset(*velocity);
    Result<graph::GaussianNoise> noise = graph::GaussianNoise::from_covariance(velocity->covariance + Eigen::Matrix3d::Identity() * change * change);
    if (!noise || !velocity->velocity_sensor.allFinite() || !velocity->angular_rate_body.allFinite()) continue;
    graph::GraphUpdate update;
    update.factors.emplace<graph::BodyVelocityFactor>(graph::X(keyframe), graph::V(keyframe), velocity->velocity_sensor, velocity->T_body_sensor,
                                                      velocity->angular_rate_body, *noise);
    graph().add_factors(update);
    ++summary_.graph_velocity_factors;
  }
}

Session::~Session() {
  worker_.reset();  // before the odometry it registers with
  wait_for_backend();
}

std::optional<std::chrono::nanoseconds> Session::registration_wait_limit(Timestamp now_in_data) const {
  // Live data (stamped by a clock synchronized with this machine's) never waits: a push() that
  // waited would hold back every IMU pose behind it. Recorded data streamed at any speed waits.
  if (std::abs((Timestamp::wall_clock_now() - now_in_data).seconds()) > config_.live_window_s) return std::nullopt;
  return std::chrono::nanoseconds(0);
}

PushStatus Session::push(std::string_view sensor, msgs::SensorMessage message) {
  if (splats_ && sensor == splats_->sensor()) {
    if (const auto* image = std::get_if<msgs::ImageMessage>(&message); image != nullptr && msgs::validate(*image).ok()) splats_->add_image(*image);
  }
  if (const auto* gnss = std::get_if<msgs::GnssMessage>(&message)) {
    if (const config::SensorConfig* configured = frontend_->config().find_sensor(sensor)) {
      gnss_without_fix_[configured->name] = gnss->fix_type < configured->fusion.min_fix;
    }
  }
  PushStatus pushed = push_message(sensor, std::move(message));
  take_splat_views();
  track_health();
  return pushed;
}

void Session::take_splat_views() {
  if (!splats_ || !latest_keyframe_) return;
  splats_->take_views([this](Timestamp time) { return frontend_->pose_at(time); }, latest_keyframe_->keyframe_id,
                      frontend_->world_correction() * latest_keyframe_uncorrected_);
}

PushStatus Session::push_message(std::string_view sensor, msgs::SensorMessage message) {
  if (const auto* detections = std::get_if<msgs::DetectionsMessage>(&message)) return push_detections(sensor, *detections);
  if (detector_) detect_objects(sensor, message);
  if (!config_.mapping) return frontend_->push(sensor, message);
  if (camera_odometry_ && camera_odometry_->handles(sensor)) return push_image(sensor, message);
  if (camera_odometry_ && camera_odometry_->visual_inertial() && sensor == camera_odometry_->imu_sensor()) {
    if (const auto* imu = std::get_if<msgs::ImuMessage>(&message)) camera_odometry_->add_imu(*imu);
  }
  if (lidar_factors_ && sensor == imu_sensor_) {
    if (const auto* imu = std::get_if<msgs::ImuMessage>(&message)) {
      if (const std::optional<estimate::ImuSample> sample = body_imu_->convert(*imu)) lidar_factors_->add_imu(*sample);
    }
  }
  if (maps_lidar() && sensor == lidar_sensor_) {
    if (auto* scan = std::get_if<msgs::PointCloudMessage>(&message)) return push_scan(std::move(*scan));
  }
  if (merger_) {
    for (std::size_t i = 0; i < merger_->size(); ++i) {
      if (sensor != merger_->secondary(i).sensor) continue;
      if (auto* scan = std::get_if<msgs::PointCloudMessage>(&message)) return push_secondary_scan(i, std::move(*scan));
    }
  }
  if (!wheel_sensor_.empty() && sensor == wheel_sensor_) {
    const auto* wheels = std::get_if<msgs::WheelOdometryMessage>(&message);
    if (planar_ && wheels != nullptr && msgs::validate(*wheels).ok()) planar_->add_wheels(*wheels, wheels->timestamp + wheel_time_offset_, T_body_wheels_);
    if (wheels != nullptr && msgs::validate(*wheels).ok() && !wheels_agree(*wheels)) {
      frontend_->note_input(sensor, wheels->timestamp);  // withheld while they slip, not silent
      ++summary_.wheel_messages_withheld;
      register_ready_scans();
      update_backend();
      return {};
    }
  }
  PushStatus pushed = frontend_->push(sensor, message);
  register_ready_scans();
  update_backend();
  return pushed;
}

bool Session::wheels_agree(const msgs::WheelOdometryMessage& wheels) {
  slip_monitor_.add_wheels(wheels.timestamp + wheel_time_offset_, 0.5 * (wheels.left_distance + wheels.right_distance));
  return !slip_monitor_.slipping();
}

void Session::flush() {
  flush_pipeline();
  take_splat_views();
  track_health();
}

void Session::flush_pipeline() {
  release_waiting_images(std::nullopt);
  frontend_->flush();
  if (!config_.mapping) return;
  register_ready_scans(/*final=*/true);
  if (worker_) worker_->wait_idle();
  take_registered();
  update_backend();
  if (planar_ && config_.mode == SessionMode::kReplay) {
    if (Status finished = planar_->finish(); !finished) logger()->warn("session: the planar graph's final optimization failed: {}", finished.error().message);
  }
  if (config_.mode == SessionMode::kRealtime || !latest_keyframe_) return;
  // Replay: the graph's final estimate over everything (what a background batch would give).
  if (Result<graph::OptimizationSummary> batch = graph().smoother().wait_for_batch(); !batch) {
    logger()->warn("session: final optimization failed: {}", batch.error().message);
    return;
  }
  follow_graph();
}

PushStatus Session::push_scan(msgs::PointCloudMessage scan) {
  ++lidar_statistics_.received;
  ++summary_.scans_received;
  auto refuse = [this](Rejection reason, const std::string& detail) {
    ++lidar_statistics_.rejected[reason];
    return PushStatus(reason, detail);
  };
  if (Status valid = msgs::validate(scan); !valid) return refuse(Rejection::kInvalid, valid.error().message);
  if (last_scan_time_ && scan.timestamp == *last_scan_time_) {
    return refuse(Rejection::kDuplicate, fmt::format("sweep at {:.6f} s repeats the previous sweep's time", scan.timestamp.seconds()));
  }
  if (last_scan_time_ && scan.timestamp < *last_scan_time_) {
    return refuse(Rejection::kOutOfOrder, fmt::format("sweep at {:.6f} s is older than the previous sweep ({:.6f} s)", scan.timestamp.seconds(),
                                              last_scan_time_->seconds()));
  }
  last_scan_time_ = scan.timestamp;
  frontend_->note_input(lidar_sensor_, scan.timestamp);  // heard, though its pose comes after registration
  to_body_clock(scan, lidar_time_offset_);
  if (!lidar_statistics_.first_time.nanoseconds()) lidar_statistics_.first_time = scan.timestamp;
  lidar_statistics_.last_time = scan.timestamp;
  const Timestamp end = sweep_end(scan);
  waiting_scans_.push_back({std::move(scan), end});
  while (waiting_scans_.size() > config_.max_waiting_scans) {
    waiting_scans_.pop_front();
    // Before the first pose the IMU is still aligning (its messages are refused the same way).
    count_refused(frontend_->latest_pose() ? Rejection::kImuBehind : Rejection::kAligning);
  }
  register_ready_scans();
  update_backend();
  return {};
}

PushStatus Session::push_secondary_scan(std::size_t index, msgs::PointCloudMessage scan) {
  SecondaryLidar& lidar = secondary_lidars_[index];
  const std::string& sensor = merger_->secondary(index).sensor;
  ++lidar.statistics.received;
  auto refuse = [&lidar](Rejection reason, const std::string& detail) {
    ++lidar.statistics.rejected[reason];
    return PushStatus(reason, detail);
  };
  if (Status valid = msgs::validate(scan); !valid) return refuse(Rejection::kInvalid, fmt::format("{}: {}", sensor, valid.error().message));
  if (lidar.last_time && scan.timestamp <= *lidar.last_time) {
    return refuse(scan.timestamp == *lidar.last_time ? Rejection::kDuplicate : Rejection::kOutOfOrder,
                  fmt::format("{}: sweep at {:.6f} s is not after the previous sweep ({:.6f} s)", sensor, scan.timestamp.seconds(),
                              lidar.last_time->seconds()));
  }
  lidar.last_time = scan.timestamp;
  frontend_->note_input(sensor, scan.timestamp);
  if (lidar.statistics.first_time.nanoseconds() == 0) lidar.statistics.first_time = scan.timestamp;
  lidar.statistics.last_time = scan.timestamp;
  to_body_clock(scan, lidar.time_offset);
  if (Status added = merger_->add(index, scan); !added) return refuse(Rejection::kInvalid, added.error().message);
  register_ready_scans();
  update_backend();
  return {};
}

PushStatus Session::push_image(std::string_view sensor, const msgs::SensorMessage& message) {
  SensorStatistics& statistics = camera_statistics_[std::string(sensor)];
  ++statistics.received;
  auto refuse = [&statistics](Rejection reason, const std::string& detail) {
    ++statistics.rejected[reason];
    return PushStatus(reason, detail);
  };
  const auto* image = std::get_if<msgs::ImageMessage>(&message);
  if (image == nullptr) return refuse(Rejection::kWrongType, fmt::format("camera {}: not an image message", sensor));
  if (Status valid = msgs::validate(*image); !valid) return refuse(Rejection::kInvalid, valid.error().message);
  if (statistics.last_time.nanoseconds() != 0 && image->timestamp <= statistics.last_time) {
    return refuse(image->timestamp == statistics.last_time ? Rejection::kDuplicate : Rejection::kOutOfOrder,
                  fmt::format("camera {}: image at {:.6f} s is not after the previous one ({:.6f} s)", sensor, image->timestamp.seconds(),
                              statistics.last_time.seconds()));
  }
  // The camera streams: heard by the timeout monitoring whether or not its frame gives a pose.
  frontend_->note_input(sensor, image->timestamp);
  // Earlier images waiting for their detections go first (frames complete in time order).
  release_waiting_images(image->timestamp);
  if (wait_for_detections(sensor, image->timestamp)) {
    camera_detections_.find(sensor)->second.waiting = *image;
    if (statistics.first_time.nanoseconds() == 0) statistics.first_time = image->timestamp;
    statistics.last_time = image->timestamp;
    return {};
  }
  return track_image(std::string(sensor), *image);
}

PushStatus Session::track_image(const std::string& sensor, const msgs::ImageMessage& image_message) {
  SensorStatistics& statistics = camera_statistics_[sensor];
  auto refuse = [&statistics](Rejection reason, const std::string& detail) {
    ++statistics.rejected[reason];
    return PushStatus(reason, detail);
  };
  const msgs::ImageMessage* image = &image_message;
  Result<std::optional<CameraOdometry::Tracked>> tracked = camera_odometry_->add(sensor, *image, static_mask_for(sensor, *image));
  if (!tracked) return refuse(Rejection::kInvalid, fmt::format("camera {}: {}", sensor, tracked.error().message));
  if (statistics.first_time.nanoseconds() == 0) statistics.first_time = image->timestamp;
  statistics.last_time = image->timestamp;
  if (!*tracked) return {};  // waiting for the rest of its frame
  const CameraOdometry::Tracked& frame = **tracked;
  for (const auto& [rig, left] : frame.left_images) {
    if (rig != 0 || left.empty()) continue;
    recent_camera_images_.emplace_back(frame.time, left.clone());
    if (recent_camera_images_.size() > static_cast<std::size_t>(kRecentCameraImages)) recent_camera_images_.pop_front();
  }
  // The camera time of each of the frame's images.
  const auto camera_time = [this, &frame](const std::string& camera) {
    const CameraOdometry::Rig& rig = *camera_odometry_->rig_of(camera);
    return frame.time - (camera == rig.left_sensor ? rig.left_offset : rig.right_offset);
  };
  // A frame not fused is counted on the left camera of each rig in it (a stereo pair is one
  // measurement); a fused one on every camera.
  const auto count_lefts = [this, &frame](Rejection reason) {
    for (const std::string& camera : frame.sensors) {
      if (camera == camera_odometry_->rig_of(camera)->left_sensor) ++camera_statistics_[camera].rejected[reason];
    }
  };
  if (frame.frame.state != vision::TrackingState::kTracking) {
    // Before the odometry's first pose: before its initialization; lost frames as lost, their
    // image's condition the health's reason.
    const bool lost = frame.frame.state == vision::TrackingState::kLost;
    count_lefts(lost ? Rejection::kTrackingLost : Rejection::kBeforeInitialization);
    // (A bounded list: a camera that never initializes keeps its newest frames.)
    constexpr size_t kInitializingFramesKept = 256;
    if (lost || initializing_frames_.size() >= kInitializingFramesKept) initializing_frames_.clear();
    if (!lost) initializing_frames_.emplace_back(frame.time, frame.sensors);
    if (lost) {
      switch (frame.image_quality.condition) {
        case vision::ImageCondition::kDark: camera_lost_reason_ = HealthReason::kDark; break;
        case vision::ImageCondition::kGlare: camera_lost_reason_ = HealthReason::kGlare; break;
        case vision::ImageCondition::kMotionBlur: camera_lost_reason_ = HealthReason::kMotionBlur; break;
        case vision::ImageCondition::kGood: camera_lost_reason_ = HealthReason::kFewFeatures; break;
      }
      logger()->debug("session: camera frame at {:.3f} s lost: {}", frame.time.seconds(), frame.frame.reason);
      for (const auto& loops : visual_loops_) loops->note_lost();
      // The cameras stream (not a timeout) though their frames are not fused.
      for (const std::string& camera : frame.sensors) frontend_->note_input(camera, camera_time(camera));
    }
    return {};
  }
  camera_lost_reason_.reset();
  if (frame.frame.keyframe && !camera_odometry_->visual_inertial()) ++summary_.map_version;  // a keyframe of the landmark map
  const Timestamp sensor_time = frame.time - camera_odometry_->left_time_offset();
  // Backend corrections since the previous frame moved the Frontend's world: the odometry's
  // world follows them (as the LiDAR odometry's does).
  if (visual_world_) visual_world_ = frontend_->world_correction() * visual_world_correction_.inverse() * *visual_world_;
  visual_world_correction_ = frontend_->world_correction();
  // The odometry's world in the Frontend's: the identity without an IMU (the odometry's world,
  // the body at its first keyframe, is the Frontend's); with an IMU the Frontend's pose at the
  // first tracked frame, once, as the LiDAR odometry's map is.
  if (!visual_world_) {
    if (!frontend_->has_imu()) {
      visual_world_ = SE3();
    } else if (const std::optional<SE3> T_world_body = frontend_->pose_at(frame.time)) {
      visual_world_ = *T_world_body * frame.T_world_body.inverse();
      if (camera_odometry_->visual_inertial()) {
        // Both worlds are gravity-aligned (z up): only heading and origin differ. Keeping the
        // filter's roll and pitch at this instant out (off by degrees after a start in motion)
        // keeps the odometry's tilt, which its IMU and images observe better.
        const Eigen::Vector3d rpy = estimate::roll_pitch_yaw(visual_world_->rotation().matrix());
        const SO3 heading = estimate::rotation_from_roll_pitch_yaw(0.0, 0.0, rpy.z());
        visual_world_ = SE3(heading, T_world_body->translation() - heading * frame.T_world_body.translation());
      }
    }
  }
  // (A monocular visual-inertial odometry is metric.)
  const bool monocular_with_imu = frontend_->has_imu() && !camera_odometry_->metric() && !camera_odometry_->visual_inertial();
  Status fused = ok_status();
  if (visual_world_ && !monocular_with_imu) {
    // Poses of the camera: 5.5 cm and 1 degree (its slow drift is not in the covariance, as
    // with the LiDAR odometry's poses). Loose enough that the IMU filter's chi-square gate
    // accepts them while it drifts between frames (bench/RESULTS.md, 2026-11-28). The
    // visual-inertial filter's poses are fused without the gate when no GNSS tells the filter
    // otherwise: it rejected its outliers feature by feature, and it integrates the same IMU with
    // the images' help, so where the two disagree (a correction after a stretch with few
    // features) it is the one to follow. With GNSS the gate stays: the fixes may rightly
    // disagree with the odometry's drift. Without any other sensor of the body's motion the gate
    // has only the motion model's guess to check the poses against (it dropped the frames of a
    // car speeding up after the first ones): the odometry's poses are the estimate.
    Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
    covariance.diagonal() << 3e-3, 3e-3, 3e-3, 3e-4, 3e-4, 3e-4;
    const config::FusionConfig& fusion = frontend_->config();
    const bool gated = configures_gnss(fusion) || (!camera_odometry_->visual_inertial() && configures_motion_beside_cameras(fusion));
    if (frame.frame.map_origin_time && !frontend_->has_imu()) fuse_map_origin(*frame.frame.map_origin_time, covariance);
    fused = frontend_->push_pose(camera_odometry_->left_sensor(), sensor_time, *visual_world_ * frame.T_world_body * camera_odometry_->T_body_left(), covariance,
                                 gated);
  }
  if (monocular_with_imu) {
    count_lefts(Rejection::kNotFused);  // monocular scale: needs visual-inertial initialization
  } else if (!visual_world_) {
    count_lefts(Rejection::kAligning);  // the Frontend has no pose at the frame's time yet
  } else if (fused) {
    for (const std::string& camera : frame.sensors) {
      ++camera_statistics_[camera].fused;
      if (camera != camera_odometry_->left_sensor()) frontend_->note_input(camera, camera_time(camera));
    }
  } else {
    logger()->debug("session: visual odometry pose not fused: {}", fused.error().message);
  }
  initializing_frames_.clear();
  if (!visual_loops_.empty() && fused && visual_world_ && latest_keyframe_ && !restart_graph_) {
    for (std::size_t i = 0; i < frame.left_images.size(); ++i) {
      add_visual_place(frame.time, frame.left_images[i].first, frame.left_images[i].second, frame.left_masks[i], frame.T_world_body);
    }
  }
  register_ready_scans();
  update_backend();
  return {};
}

void Session::fuse_map_origin(double origin_time, const Eigen::Matrix<double, 6, 6>& covariance) {
  // The frame is the one reported initializing at that time (the odometry's clock is the frame
  // time in seconds); the world origin is its camera's pose.
  const auto origin = std::find_if(initializing_frames_.begin(), initializing_frames_.end(),
                                   [origin_time](const auto& frame) { return frame.first.seconds() == origin_time; });
  if (origin == initializing_frames_.end()) return;
  const Timestamp sensor_time = origin->first - camera_odometry_->left_time_offset();
  if (!frontend_->push_pose(camera_odometry_->left_sensor(), sensor_time, *visual_world_ * camera_odometry_->T_body_left(), covariance, false)) return;
  // Counted before its initialization when it came: fused now.
  for (const std::string& camera : origin->second) {
    SensorStatistics& statistics = camera_statistics_[camera];
    if (camera == camera_odometry_->rig_of(camera)->left_sensor) {
      const auto before = statistics.rejected.find(Rejection::kBeforeInitialization);
      if (before != statistics.rejected.end() && --before->second == 0) statistics.rejected.erase(before);
    }
    ++statistics.fused;
  }
}

void Session::add_visual_place(Timestamp time, int rig, const cv::Mat& image, const vision::StaticMask& static_mask, const SE3& T_odometry_body) {
  const std::optional<SE3> T_world_body = frontend_->pose_at(time);
  if (!T_world_body) return;
  // Both before the Frontend's corrections, where their relative motion is the filter's.
  const SE3 T_anchor_body = latest_keyframe_uncorrected_.inverse() * frontend_->world_correction().inverse() * *T_world_body;
  Result<std::optional<VisualLoopClosures::LoopFactor>> loop =
      visual_loops_[static_cast<size_t>(rig)]->add(time, image, static_mask, T_odometry_body, latest_keyframe_->keyframe_id, latest_keyframe_->timestamp, T_anchor_body);
  if (!loop) {
    logger()->warn("session: camera image at {:.3f} s not added as a place: {}", time.seconds(), loop.error().message);
    return;
  }
  if (!*loop) return;
  const VisualLoopClosures::LoopFactor& factor = **loop;
  if (factor.from_keyframe == factor.to_keyframe) return;
  if (Status added = add_loop_factor(factor.from_keyframe, factor.to_keyframe, factor.T_from_to, factor.covariance); !added) {
    logger()->warn("session: visual loop closure not added: {}", added.error().message);
    return;
  }
  ++summary_.loop_closures;
  logger()->info("session: visual loop closed between keyframes {} and {}: {} inliers, cameras {:.2f} m apart", factor.from_keyframe,
                 factor.to_keyframe, factor.loop.inliers, factor.loop.T_place_current.translation().norm());
}

void Session::count_refused(Rejection reason) {
  ++lidar_statistics_.rejected[reason];
  ++summary_.scans_refused;
  if (reason == Rejection::kNotRegistered) ++registration_failures_;
}

std::vector<SensorHealth> Session::health() const {
  // A LiDAR whose sweeps fail this many times in a row no longer constrains the estimate.
  constexpr int kFailuresForNotRegistered = 3;
  std::vector<SensorHealth> health;
  for (const SensorStatistics& sensor : summary().sensors) {
    SensorHealth entry{sensor.name, sensor.modality, HealthState::kOk, HealthReason::kNone};
    const auto degraded = [&entry](HealthReason reason) {
      entry.state = HealthState::kDegraded;
      entry.reason = reason;
    };
    const auto applied = last_update_applied_.find(sensor.name);
    if (sensor.fused == 0 && sensor.rejected.count(Rejection::kNotFused) != 0) {
      entry = {sensor.name, sensor.modality, HealthState::kLost, HealthReason::kNotFused};
    } else if (sensor.name == wheel_sensor_ && slip_monitor_.slipping()) {
      degraded(HealthReason::kSlip);  // withheld from the Frontend, which may time them out
    } else if (sensor.timed_out) {
      entry = {sensor.name, sensor.modality, HealthState::kLost, HealthReason::kTimeout};
    } else if (sensor.name == lidar_sensor_ && maps_lidar() && registration_failures_ >= kFailuresForNotRegistered) {
      degraded(HealthReason::kNotRegistered);
    } else if (sensor.name == lidar_sensor_ && maps_lidar() && last_sweep_degenerate_) {
      degraded(HealthReason::kDegenerateGeometry);
    } else if (sensor.name == lidar_sensor_ && odometry_ && last_sweep_weather_) {
      degraded(HealthReason::kWeather);
    } else if (const auto no_fix = gnss_without_fix_.find(sensor.name); no_fix != gnss_without_fix_.end() && no_fix->second) {
      degraded(HealthReason::kNoFix);
    } else if (camera_lost_reason_ && camera_odometry_ && camera_odometry_->handles(sensor.name)) {
      degraded(*camera_lost_reason_);
    } else if (applied != last_update_applied_.end() && !applied->second) {
      degraded(HealthReason::kGated);
    }
    health.push_back(std::move(entry));
  }
  return health;
}

void Session::track_health() {
  constexpr double kInterval = 0.2;  // s of data time
  const std::optional<msgs::PoseEstimate> latest = frontend_->latest_pose();
  if (!latest || (last_health_time_ && (latest->timestamp - *last_health_time_).seconds() < kInterval)) return;
  last_health_time_ = latest->timestamp;
  std::vector<SensorHealth> now = health();
  for (std::size_t i = 0; i < now.size(); ++i) {
    const bool changed = i >= last_health_.size() || now[i].state != last_health_[i].state || now[i].reason != last_health_[i].reason;
    if (!changed) continue;
    health_changes_.push_back({latest->timestamp, now[i]});
    if (i < last_health_.size()) {
      logger()->info("session: {} is {}{}{}", now[i].sensor, to_string(now[i].state), now[i].reason == HealthReason::kNone ? "" : ": ",
                     to_string(now[i].reason));
    }
  }
  last_health_ = std::move(now);
}

void Session::register_ready_scans(bool final) {
  take_registered();
  while (!waiting_scans_.empty()) {
    const bool has_imu = frontend_->has_imu();
    if (!has_imu) frontend_->propagate_to(waiting_scans_.front().end);
    const std::optional<msgs::PoseEstimate> latest = frontend_->latest_pose();
    if (latest && !first_pose_time_) first_pose_time_ = latest->timestamp;
    if (has_imu && (!latest || latest->timestamp < waiting_scans_.front().end)) break;
    const Timestamp now = has_imu ? latest->timestamp : waiting_scans_.front().end;
    if (merger_ && has_imu && !final && !merger_->ready(waiting_scans_.front().end, now)) break;
    const msgs::PointCloudMessage scan = std::move(waiting_scans_.front().scan);
    waiting_scans_.pop_front();
    if (planar_) {
      on_planar_scan(scan);
      continue;
    }
    Result<LidarInertialOdometry::PreparedScan> prepared = odometry_->prepare(scan);
    if (prepared && merger_) merger_->merge(prepared->cloud, prepared->time);
    if (prepared && semantic_projection_) mask_moving_points(*prepared);
    if (!prepared) {
      logger()->debug("session: sweep at {:.3f} s not registered: {}", scan.timestamp.seconds(), prepared.error().message);
      // A sweep that began before the first pose has no motion to start from (the IMU aligned).
      count_refused(first_pose_time_ && scan.timestamp >= *first_pose_time_ ? Rejection::kNotRegistered : Rejection::kAligning);
    } else if (worker_) {
      const std::size_t dropped = worker_->submit(std::move(prepared).value(), registration_wait_limit(now));
      for (std::size_t i = 0; i < dropped; ++i) count_refused(Rejection::kRegistrationBehind);
    } else {
      on_registered(odometry_->register_scan(*prepared));
    }
  }
  take_registered();
}

void Session::check_wheels(Timestamp sweep_time, const std::optional<SE3>& T_previous_current, bool reliable) {
  if (wheel_sensor_.empty()) return;
  // The LiDAR's motion since the previous registered sweep, as the wheel frame's forward travel.
  if (last_sweep_time_ && T_previous_current) {
    const SE3 T_body_body = T_body_lidar_ * *T_previous_current * T_body_lidar_.inverse();
    const SE3 T_wheels_wheels = T_body_wheels_.inverse() * T_body_body * T_body_wheels_;
    const bool was_slipping = slip_monitor_.slipping();
    slip_monitor_.add_lidar_motion(*last_sweep_time_, sweep_time, T_wheels_wheels.translation().x(), reliable);
    if (slip_monitor_.slipping() != was_slipping) {
      logger()->warn("session: wheels {} the LiDAR odometry ({:+.3f} m over {:.1f} s){}", slip_monitor_.slipping() ? "disagree with" : "agree again with",
                     slip_monitor_.last_difference(), config_.wheel_slip.window_s, slip_monitor_.slipping() ? ": not fused while they slip" : "");
    }
    summary_.wheel_slip_episodes = slip_monitor_.episodes();
  }
  last_sweep_time_ = sweep_time;
}

void Session::on_planar_scan(const msgs::PointCloudMessage& scan) {
  Result<PlanarLaserOdometry::Outcome> outcome = planar_->add_scan(scan);
  if (!outcome) {
    logger()->debug("session: scan at {:.3f} s not matched: {}", scan.timestamp.seconds(), outcome.error().message);
    count_refused(first_pose_time_ && scan.timestamp >= *first_pose_time_ ? Rejection::kNotRegistered : Rejection::kAligning);
    return;
  }
  const PlanarScanEstimate& estimate = outcome->estimate;
  ++lidar_statistics_.fused;
  ++summary_.scans_registered;
  summary_.degenerate_scans += estimate.degenerate ? 1 : 0;
  last_sweep_degenerate_ = estimate.degenerate;
  registration_failures_ = estimate.scan_matched ? 0 : registration_failures_ + 1;
  const PlanarLaserSlamSummary& slam = planar_->slam().summary();
  summary_.map_keyframes = slam.keyframes;
  summary_.loop_candidates = slam.loop_candidates;
  summary_.loop_closures = slam.loop_closures;
  if (estimate.keyframe || estimate.loop_closures_added > 0) ++summary_.map_version;
  // The laser's motion since the previous scan (both on the graph as it was before this scan's
  // loop closures) checks the wheels.
  const SE3 T_world_laser_matched = lifted(estimate.T_map_laser_matched * planar_part(outcome->T_world_laser).inverse()) * outcome->T_world_laser;
  check_wheels(scan.timestamp, last_lidar_pose_ ? std::optional<SE3>(last_lidar_pose_->inverse() * T_world_laser_matched) : std::nullopt,
               estimate.scan_matched && !estimate.degenerate);
  last_lidar_pose_ = outcome->T_world_laser;
}

void Session::take_registered() {
  if (!worker_) return;
  for (Result<LidarInertialOdometry::RegisteredScan>& registered : worker_->take_done()) on_registered(std::move(registered));
}

void Session::on_registered(Result<LidarInertialOdometry::RegisteredScan> result) {
  Result<LidarInertialOdometry::RegisteredScan> fused = odometry_->fuse(std::move(result));
  if (!fused) {
    logger()->debug("session: sweep not fused: {}", fused.error().message);
    count_refused(Rejection::kNotRegistered);
    return;
  }
  const LidarInertialOdometry::RegisteredScan& registered = *fused;
  summary_.last_registration_ms = 1e3 * registered.seconds;
  ++lidar_statistics_.fused;
  ++summary_.scans_registered;
  summary_.degenerate_scans += registered.estimate.degenerate ? 1 : 0;
  summary_.weather_degraded_scans += registered.estimate.weather_degraded ? 1 : 0;
  last_sweep_degenerate_ = registered.estimate.degenerate;
  last_sweep_weather_ = registered.estimate.weather_degraded;
  registration_failures_ = 0;
  if (scan_callback_) scan_callback_(registered);
  const lidar::LidarOdometryEstimate& estimate = registered.estimate;
  if (lidar_factors_) {
    const double weather = estimate.weather_degraded ? config_.lidar_odometry.weather_covariance_scale : 1.0;
    lidar_factors_->add_sweep(estimate.time, estimate.T_world_lidar, weather * estimate.covariance, estimate.first_scan);
  }
  check_wheels(estimate.time, estimate.first_scan ? std::nullopt : std::optional<SE3>(estimate.T_previous_current),
               !estimate.degenerate && !estimate.weather_degraded);
  const SE3& T_world_lidar = registered.T_world_lidar;
  if (last_lidar_pose_) path_ += (last_lidar_pose_->inverse() * T_world_lidar).translation().norm();
  last_lidar_pose_ = T_world_lidar;
  // A map keyframe: the first sweep after a new Frontend keyframe, once the LiDAR moved enough.
  // Every other sweep goes into the grids only (free space needs many rays through a cell).
  bool keyframe = latest_keyframe_ && !(last_anchor_ && *last_anchor_ == latest_keyframe_->keyframe_id);
  if (keyframe && last_offered_map_keyframe_) {
    const SE3 since = last_offered_map_keyframe_->inverse() * T_world_lidar;
    keyframe = since.translation().norm() >= config_.map_keyframe_distance || since.rotation().log().norm() >= config_.map_keyframe_angle;
  }
  auto [points, classes] = label_sweep(estimate.time, registered.points);
  if (keyframe) return add_map_keyframe(estimate.time, T_world_lidar, points, classes);
  if (!classes.empty()) {
    if (Status voted = map_builder_.add_class_votes(T_world_lidar, points, classes); !voted) {
      logger()->warn("session: a sweep's segmentation classes not kept: {}", voted.error().message);
    }
  }
  cloud::PointCloud cloud;
  cloud.positions = std::move(points);
  if (Status inserted = map_builder_.insert(T_world_lidar, cloud, maps::ScanUse::kGridsOnly); !inserted) {
    logger()->warn("session: sweep not inserted into the map's grids: {}", inserted.error().message);
  }
}

void Session::add_map_keyframe(Timestamp time, const SE3& T_world_lidar, const std::vector<Eigen::Vector3f>& points, const std::vector<uint16_t>& point_classes) {
  // The anchor (the newest keyframe) as the graph got it, in today's world.
  const uint64_t anchor = latest_keyframe_->keyframe_id;
  const SE3 T_world_anchor = frontend_->world_correction() * latest_keyframe_uncorrected_;
  if (pending_revisit_) {  // the previous revisit was searched: the detector forgets it now
    loop_closures_.remove_newest();
    pending_revisit_.reset();
  }
  last_anchor_ = anchor;
  last_offered_map_keyframe_ = T_world_lidar;
  const bool aligned = loop_closures_.size() == map_keyframes_.size();
  const bool revisit = config_.loop_closure && aligned &&
                       loop_closures_.covered(T_world_lidar, path_, [this](std::size_t k) { return map_keyframe_pose(k); });
  cloud::PointCloud cloud;
  cloud.positions = points;
  if (Status inserted = map_builder_.insert(T_world_lidar, cloud, revisit ? maps::ScanUse::kGridsOnly : maps::ScanUse::kAllLayers, point_classes);
      !inserted) {
    logger()->warn("session: map keyframe not inserted: {}", inserted.error().message);
    return;
  }
  const MapKeyframe keyframe{time, anchor, T_world_anchor.inverse() * T_world_lidar, T_world_lidar};
  const Result<std::size_t> added = loop_closures_.add_keyframe(points, path_);
  if (!added) logger()->warn("session: map keyframe not added to loop closure: {}", added.error().message);
  const bool searchable = added && aligned;
  if (revisit) {
    ++summary_.map_revisits;
    if (added) pending_revisit_ = keyframe;
    if (searchable) detect_lidar_loop();
    return;
  }
  map_keyframe_of_[anchor] = map_keyframes_.size();
  map_keyframes_.push_back(keyframe);
  if (splats_) splats_->add_points(cloud::transformed(cloud, T_world_lidar).positions);
  ++summary_.map_keyframes;
  ++summary_.map_version;
  if (map_update_callback_) {
    msgs::MapUpdate update;
    update.version = summary_.map_version;
    update.timestamp = latest_keyframe_ ? latest_keyframe_->timestamp : Timestamp();
    msgs::PointLayer layer;
    layer.points = cloud::transformed(cloud, T_world_lidar).positions;
    update.added_points = std::move(layer);
    map_update_callback_(update);
  }
  if (searchable) detect_lidar_loop();
}

void Session::detect_lidar_loop() {
  if (!config_.loop_closure) return;
  update_backend();  // the anchor into the graph before its pose is looked up
  const std::optional<lidar::LoopClosure> loop = loop_closures_.detect([this](std::size_t k) { return map_keyframe_pose(k); });
  summary_.loop_candidates = loop_closures_.candidates();
  if (!loop) return;
  const MapKeyframe& from = map_keyframe(loop->from);
  const MapKeyframe& to = map_keyframe(loop->to);
  const SE3 T_anchors = from.T_anchor_lidar * loop->T_from_to * to.T_anchor_lidar.inverse();
  if (Status added = add_loop_factor(from.anchor, to.anchor, T_anchors, std::nullopt); !added) {
    logger()->warn("session: loop closure not added: {}", added.error().message);
    return;
  }
  ++summary_.loop_closures;
  logger()->info("session: loop closed between keyframes {} and {} (inlier RMSE {:.3f} m)", from.anchor, to.anchor,
                 loop->inlier_rmse);
  update_backend();
}

const Session::MapKeyframe& Session::map_keyframe(std::size_t k) const {
  return k == map_keyframes_.size() && pending_revisit_ ? *pending_revisit_ : map_keyframes_.at(k);
}

SE3 Session::map_keyframe_pose(std::size_t k) const {
  const MapKeyframe& keyframe = map_keyframe(k);
  const std::optional<SE3> anchor = graph().optimized_pose(keyframe.anchor);
  return anchor ? *anchor * keyframe.T_anchor_lidar : keyframe.T_world_lidar;
}

Status Session::add_loop_factor(uint64_t from, uint64_t to, const SE3& T_from_to,
                                       const std::optional<Eigen::Matrix<double, 6, 6>>& covariance) {
  Eigen::Matrix<double, 6, 6> loop_covariance = Eigen::Matrix<double, 6, 6>::Zero();
  loop_covariance.diagonal() << Eigen::Vector3d::Constant(config_.loop_translation_sigma * config_.loop_translation_sigma),
      Eigen::Vector3d::Constant(config_.loop_rotation_sigma * config_.loop_rotation_sigma);
  return graph().add_loop_closure(from, to, T_from_to, covariance.value_or(loop_covariance));
}

void Session::update_backend() {
  if (!backend_thread_) {
    finish_backend_update(graph_->process(frontend_.get()));
    return;
  }
  // On the backend thread: an update starts once something was added, and is waited for where
  // the graph is next used (graph()). One that may correct the Frontend (a loop closure) runs
  // here: the correction lands where it would inline.
  if (!graph_touched_) return;
  KeyframeGraph& keyframe_graph = graph();
  graph_touched_ = false;
  if (!keyframe_graph.has_pending_work()) return;
  if (keyframe_graph.may_correct_frontend()) {
    finish_backend_update(keyframe_graph.process(frontend_.get()));
    return;
  }
  backend_update_ = std::async(std::launch::async, [&keyframe_graph] { return keyframe_graph.process(nullptr); });
}

void Session::wait_for_backend() const {
  if (backend_update_.valid()) backend_result_.emplace(backend_update_.get());
}

KeyframeGraph& Session::graph() {
  wait_for_backend();
  graph_touched_ = true;
  if (backend_result_) {
    Result<KeyframeGraphUpdate> update = std::move(*backend_result_);
    backend_result_.reset();
    finish_backend_update(std::move(update));
  }
  return *graph_;
}

const KeyframeGraph& Session::graph() const {
  wait_for_backend();
  return *graph_;
}

void Session::finish_backend_update(Result<KeyframeGraphUpdate> update) {
  if (!update) {
    logger()->warn("session: backend update failed: {}", update.error().message);
    return;
  }
  if (update->keyframes_left_window > 0 && camera_odometry_ && config_.visual_inertial_factors) {
    if (VisualInertialFactors* factors = camera_odometry_->keyframe_factors(); factors != nullptr) {
      factors->forget_landmarks(update->marginalized_landmarks);
      if (const std::optional<uint64_t> start = graph().window_start()) factors->set_window_start(*start);
    }
  }
  // The graph holds the world: the LiDAR map frame is held, so that it does not take up the filter's drift.
  if (follows_graph_ && update->corrected_session && odometry_) odometry_->hold_map_frame();
  if (update->factors_added == 0) return;
  summary_.last_correction_m = update->correction_translation_m;
  follow_graph();
}

void Session::follow_graph() {
  if (splats_) splats_->move_views([this](uint64_t keyframe) { return graph().optimized_pose(keyframe); });
  // Map keyframes whose keyframe moved follow it.
  std::map<uint64_t, SE3> moved;
  for (std::size_t k = 0; k < map_keyframes_.size(); ++k) {
    const SE3 T_world_lidar = map_keyframe_pose(k);
    const SE3 change = map_keyframes_[k].T_world_lidar.inverse() * T_world_lidar;
    if (change.translation().norm() < kMapMoveTranslation && change.rotation().log().norm() < kMapMoveRotation) continue;
    moved[restored_keyframes_.size() + k] = T_world_lidar;  // the map builder's number: restored ones first
    map_keyframes_[k].T_world_lidar = T_world_lidar;
  }
  move_map_keyframes(moved);
}

void Session::move_map_keyframes(const std::map<uint64_t, SE3>& moved) {
  if (moved.empty()) return;
  if (Status corrected = map_builder_.correct_poses(moved); !corrected) {
    logger()->warn("session: map not corrected: {}", corrected.error().message);
    return;
  }
  ++summary_.map_version;
  if (map_update_callback_) {
    msgs::MapUpdate update_message;
    update_message.version = summary_.map_version;
    update_message.timestamp = latest_keyframe_ ? latest_keyframe_->timestamp : Timestamp();
    update_message.full_replacement = true;
    if (map_builder_.point_map()) {
      msgs::FusionMap map;
      map_builder_.write_layers(map);
      update_message.added_points = std::move(map.points);
    }
    map_update_callback_(update_message);
  }
}

Result<LoopClosureOutcome> Session::close_loop(const LoopClosureRequest& request) {
  if (request.from_keyframe.has_value() != request.to_keyframe.has_value()) {
    return Error("invalid: give both from_keyframe and to_keyframe, or neither");
  }
  if (request.T_from_to && !request.from_keyframe) return Error("invalid: a relative pose needs from_keyframe and to_keyframe");
  if (request.T_from_to && !request.T_from_to->matrix().allFinite()) return Error("invalid: the relative pose is not finite");
  update_backend();
  for (const std::optional<uint64_t>& id : {request.from_keyframe, request.to_keyframe}) {
    if (id && !graph().keyframe_time(*id)) return Error(fmt::format("not_found: keyframe {} is unknown", *id));
  }
  LoopClosureOutcome outcome;
  if (request.T_from_to) {
    outcome.from_keyframe = *request.from_keyframe;
    outcome.to_keyframe = *request.to_keyframe;
    outcome.T_from_to = *request.T_from_to;
  } else {
    std::optional<lidar::LoopClosure> loop;
    const auto pose = [this](std::size_t k) { return map_keyframe_pose(k); };
    if (request.from_keyframe) {
      const auto from = map_keyframe_of_.find(*request.from_keyframe);
      const auto to = map_keyframe_of_.find(*request.to_keyframe);
      if (from == map_keyframe_of_.end() || to == map_keyframe_of_.end()) {
        return Error(fmt::format("not_found: keyframe {} has no scan (map keyframes: {})",
                                 from == map_keyframe_of_.end() ? *request.from_keyframe : *request.to_keyframe, map_keyframes_.size()));
      }
      Result<lidar::LoopClosure> verified =
          loop_closures_.verify(from->second, to->second, pose(from->second).inverse() * pose(to->second), pose);
      if (!verified) {
        return Error(fmt::format("not_verified: keyframes {} -> {} (map keyframes {} -> {}): {}", *request.from_keyframe,
                                 *request.to_keyframe, from->second, to->second, verified.error().message));
      }
      loop = *verified;
    } else {
      loop = loop_closures_.detect(pose);
      summary_.loop_candidates = loop_closures_.candidates();
      if (!loop) return Error("not_found: no verified loop closure for the newest map keyframe");
    }
    const MapKeyframe& from = map_keyframe(loop->from);
    const MapKeyframe& to = map_keyframe(loop->to);
    outcome.from_keyframe = from.anchor;
    outcome.to_keyframe = to.anchor;
    outcome.T_from_to = from.T_anchor_lidar * loop->T_from_to * to.T_anchor_lidar.inverse();
    outcome.registered = true;
    outcome.inlier_rmse = loop->inlier_rmse;
    outcome.inlier_fraction = loop->inlier_fraction;
  }
  HANZO_RETURN_IF_ERROR(add_loop_factor(outcome.from_keyframe, outcome.to_keyframe, outcome.T_from_to, request.covariance));
  ++summary_.manual_loop_closures;
  update_backend();
  outcome.correction_m = summary_.last_correction_m;
  return outcome;
}

Result<RelocalizationOutcome> Session::relocalize(const lidar::MapLocalizer& map, const RelocalizationRequest& request) {
  if (request.T_map_body_guess && !request.T_map_body_guess->matrix().allFinite()) return Error("invalid: the guess is not finite");
  if (!(request.linear_window >= 0) || !(request.angular_window >= 0)) {
    return Error("invalid: linear_window and angular_window must be finite and >= 0");
  }
  update_backend();
  if (map_keyframes_.empty() || !latest_keyframe_) {
    return Error("not_ready: no LiDAR sweep has been mapped yet (the session relocalizes its newest map keyframe)");
  }
  // The newest map keyframe's sweep with up to two before it, in its frame.
  const std::size_t newest = map_keyframes_.size() - 1;
  const SE3 T_world_newest = map_keyframe_pose(newest);
  std::vector<Eigen::Vector3f> sweep;
  for (std::size_t k = newest >= 2 ? newest - 2 : 0; k <= newest; ++k) {
    cloud::PointCloud keyframe;
    keyframe.positions = loop_closures_.points(k);
    const std::vector<Eigen::Vector3f> points = cloud::transformed(keyframe, T_world_newest.inverse() * map_keyframe_pose(k)).positions;
    sweep.insert(sweep.end(), points.begin(), points.end());
  }
  lidar::MapLocalizationQuery query;
  if (request.T_map_body_guess) {
    // The guess is for the body now; the sweep is older: carry it back by the session's motion.
    const std::optional<msgs::PoseEstimate> now = frontend_->latest_pose();
    if (!now) return Error("not_ready: the session has no pose yet");
    query.T_map_sensor_guess = *request.T_map_body_guess * now->T_world_body.to_se3().inverse() * T_world_newest;
    query.linear_window = request.linear_window;
    query.angular_window = request.angular_window;
  }
  Result<lidar::MapLocalization> localized = map.localize(sweep, T_world_newest.rotation(), query);
  if (!localized) return Error("not_found: " + localized.error().message);

  RelocalizationOutcome outcome;
  outcome.localization = *localized;
  outcome.T_map_lidar = localized->T_map_sensor;
  outcome.T_map_world = localized->T_map_sensor * T_world_newest.inverse();
  outcome.keyframe_id = latest_keyframe_->keyframe_id;
  double moved_m = 0.0;
  HANZO_ASSIGN_OR_RETURN(moved_m, move_world_onto_map(outcome.T_map_world));
  logger()->info("session: relocalized in the map (moved {:.2f} m; 2D score {:.2f}, RMSE {:.3f} m)", moved_m, localized->score, localized->inlier_rmse);
  return outcome;
}

Result<double> Session::move_world_onto_map(const SE3& T_map_world) {
  // The session's belief of its newest keyframe, moved onto the map (Frontend::apply_correction
  // composes with the corrections applied before).
  const SE3 belief = frontend_->world_correction() * latest_keyframe_->T_world_body.to_se3();
  HANZO_RETURN_IF_ERROR(with_context(frontend_->apply_correction(latest_keyframe_->keyframe_id, T_map_world * belief), "invalid"));
  // The graph holds the old world: a fresh one starts at the next keyframe; the map moves rigidly
  // and its keyframes stay there (their anchors are not in the new graph).
  std::map<uint64_t, SE3> moved;  // by the map builder's number: restored keyframes first
  for (std::size_t r = 0; r < restored_keyframes_.size(); ++r) {
    msgs::LidarKeyframe& keyframe = restored_keyframes_[r];
    keyframe.T_world_lidar = msgs::Pose::from_se3(T_map_world * keyframe.T_world_lidar.to_se3());
    moved[r] = keyframe.T_world_lidar.to_se3();
  }
  for (std::size_t k = 0; k < map_keyframes_.size(); ++k) {
    map_keyframes_[k].T_world_lidar = T_map_world * map_keyframe_pose(k);
    moved[restored_keyframes_.size() + k] = map_keyframes_[k].T_world_lidar;
  }
  if (follows_graph_) {
    // The new graph gets no fixes (the world is the map's now): the filter fuses them again, and
    // the graph corrects it at loop closures.
    follows_graph_ = false;
    frontend_->set_gnss_positions_to_backend(false);
    config_.backend.correct_on_loop_closures_only = true;
    config_.backend.batch_interval_s = 0.0;
  }
  graph();  // a running update of the old graph finishes first
  graph_ = std::make_unique<KeyframeGraph>(config_.backend);
  restart_graph_ = true;
  move_map_keyframes(moved);
  // The visual odometry's world follows now (map() writes its landmarks through it).
  if (visual_world_) visual_world_ = frontend_->world_correction() * visual_world_correction_.inverse() * *visual_world_;
  visual_world_correction_ = frontend_->world_correction();
  ++summary_.relocalizations;
  summary_.last_correction_m = ((T_map_world * belief).translation() - belief.translation()).norm();
  return summary_.last_correction_m;
}

msgs::FusionMap Session::map() const {
  msgs::FusionMap map;
  if (planar_) {
    if (Result<msgs::FusionMap> planar = planar_->map(config_.map); planar) {
      map = std::move(planar).value();
    } else {
      logger()->warn("session: the planar laser's map: {}", planar.error().message);
    }
  } else {
    map_builder_.write_map(map);
    if (loop_closures_.size() >= map_keyframes_.size() && !(map_keyframes_.empty() && restored_keyframes_.empty())) {
      msgs::LidarKeyframeLayer keyframes;
      keyframes.keyframes = restored_keyframes_;
      for (std::size_t k = 0; k < map_keyframes_.size(); ++k) {
        keyframes.keyframes.push_back({map_keyframes_[k].time, msgs::Pose::from_se3(map_keyframes_[k].T_world_lidar), loop_closures_.points(k), 0});
      }
      map.lidar_keyframes = std::move(keyframes);
    }
  }
  if (camera_odometry_ && visual_world_) {
    // The odometry's world (its left camera at the first keyframe) in the Session's.
    msgs::VisualLandmarkLayer layer = camera_odometry_->landmark_layer();
    if (!layer.positions.empty()) {
      const SE3 T_world_odometry = *visual_world_ * camera_odometry_->T_body_left();
      for (Eigen::Vector3f& position : layer.positions) position = (T_world_odometry * position.cast<double>()).cast<float>();
      for (msgs::VisualKeyframe& keyframe : layer.keyframes) keyframe.T_world_camera = msgs::Pose::from_se3(T_world_odometry * keyframe.T_world_camera.to_se3());
      map.visual_landmarks = std::move(layer);
    }
  }
  if (splats_) map.gaussian_splats = splats_->layer();
  map.version = summary_.map_version;
  map.provenance.algorithm = planar_ ? "pipeline/session (planar laser)" : "pipeline/session";
  return map;
}

Status Session::restore_map(const msgs::FusionMap& map) {
  if (!map.lidar_keyframes || map.lidar_keyframes->keyframes.empty()) return Error("restore map: the map has no LiDAR keyframes");
  if (!odometry_) return Error("restore map: the session has no 3D LiDAR odometry");
  if (lidar_statistics_.received > 0) return Error("restore map: sweeps came already");
  const std::vector<msgs::LidarKeyframe>& keyframes = map.lidar_keyframes->keyframes;
  const Eigen::Vector3d newest = keyframes.back().T_world_lidar.position;
  std::vector<LidarInertialOdometry::SeedKeyframe> seed;
  for (const msgs::LidarKeyframe& keyframe : keyframes) {
    const SE3 T_world_lidar = keyframe.T_world_lidar.to_se3();
    cloud::PointCloud cloud;
    cloud.positions = keyframe.points;
    if (Status inserted = map_builder_.insert(T_world_lidar, cloud); !inserted) {
      logger()->warn("session: a restored keyframe not in the map: {}", inserted.error().message);
      continue;
    }
    if ((T_world_lidar.translation() - newest).norm() <= config_.lidar_odometry.odometry.map.max_distance) {
      seed.push_back({T_world_lidar, keyframe.points});
    }
    restored_keyframes_.push_back({keyframe.time, keyframe.T_world_lidar, keyframe.points, 0});
  }
  odometry_->seed_map(std::move(seed));
  summary_.map_keyframes += restored_keyframes_.size();
  ++summary_.map_version;
  logger()->info("session: {} keyframes of its stored map restored", restored_keyframes_.size());
  return ok_status();
}

SessionSummary Session::summary() const {
  SessionSummary summary = frontend_->summary();
  for (SensorStatistics& sensor : summary.sensors) {
    if (!maps_lidar() || sensor.name != lidar_sensor_) continue;
    // Sweeps come here, not through Frontend::push: our counts; the Frontend's timeout and
    // consistency monitoring of the fused poses stay.
    sensor.received = lidar_statistics_.received;
    sensor.fused = lidar_statistics_.fused;
    sensor.rejected = lidar_statistics_.rejected;
    sensor.first_time = lidar_statistics_.first_time;
    sensor.last_time = lidar_statistics_.last_time;
  }
  for (SensorStatistics& sensor : summary.sensors) {
    for (std::size_t i = 0; merger_ && i < merger_->size(); ++i) {
      if (sensor.name != merger_->secondary(i).sensor) continue;
      // Sweeps come here and join the first LiDAR's: fused when their points did.
      const SensorStatistics& input = secondary_lidars_[i].statistics;
      const LidarSweepMergerStatistics& merged = merger_->statistics(i);
      sensor.received = input.received;
      sensor.rejected = input.rejected;
      sensor.fused = merged.merged_sweeps;
      if (merged.late_sweeps > 0) sensor.rejected[Rejection::kNotFused] = merged.late_sweeps;
      sensor.first_time = input.first_time;
      sensor.last_time = input.last_time;
    }
  }
  // The left camera's poses go to the Frontend, which applies or gates them: its counts say
  // how many frames were fused (a stereo pair is one measurement, counted on both cameras).
  std::optional<SensorStatistics> pose_outcomes;
  if (camera_odometry_) {
    for (const SensorStatistics& sensor : summary.sensors) {
      if (sensor.name == camera_odometry_->left_sensor()) pose_outcomes = sensor;
    }
  }
  for (SensorStatistics& sensor : summary.sensors) {
    const auto camera = camera_statistics_.find(sensor.name);
    if (camera == camera_statistics_.end()) continue;
    // Images come here, not through Frontend::push: our counts of the images, the Frontend's
    // of the poses it fused or gated; its monitoring of the fused poses stays.
    sensor.received = camera->second.received;
    sensor.rejected = camera->second.rejected;
    // A stereo pair (an RGB-D camera) is one measurement, its outcomes counted on the left
    // camera: the right (depth) one shows the same, so that each camera's images add up.
    const CameraOdometry::Rig* rig = camera_odometry_ ? camera_odometry_->rig_of(sensor.name) : nullptr;
    if (rig != nullptr && !rig->right_sensor.empty() && sensor.name == rig->right_sensor) {
      const auto left = camera_statistics_.find(rig->left_sensor);
      if (left != camera_statistics_.end()) {
        for (const auto& [reason, count] : left->second.rejected) {
          if (!is_input_check(reason)) sensor.rejected[reason] += count;
        }
      }
    }
    sensor.fused = camera->second.fused;
    if (pose_outcomes) {
      sensor.fused = std::min(camera->second.fused, pose_outcomes->fused);
      for (const auto& [reason, count] : pose_outcomes->rejected) {
        if (!is_input_check(reason)) sensor.rejected[reason] += count;
      }
    }
    sensor.first_time = camera->second.first_time;
    sensor.last_time = camera->second.last_time;
  }
  for (SensorStatistics& sensor : summary.sensors) {
    if (sensor.name != wheel_sensor_ || summary_.wheel_messages_withheld == 0) continue;
    sensor.received += summary_.wheel_messages_withheld;  // they never reached the Frontend
    sensor.rejected[Rejection::kSlip] = summary_.wheel_messages_withheld;
  }
  return summary;
}

MappingSummary Session::mapping_summary() const {
  MappingSummary summary = summary_;
  summary.masked_image_share = summary_.images_masked > 0 ? masked_share_sum_ / static_cast<double>(summary_.images_masked) : 0.0;
  summary.detector_ms = summary_.detections_computed > 0 ? detector_ms_sum_ / static_cast<double>(summary_.detections_computed) : 0.0;
  if (camera_odometry_) {
    const vision::VisualOdometrySummary visual = camera_odometry_->summary();
    summary.camera_frames_tracked = static_cast<uint64_t>(visual.tracked_frames);
    summary.camera_frames_lost = static_cast<uint64_t>(visual.lost_frames);
    summary.visual_keyframes = static_cast<uint64_t>(visual.keyframes);
    summary.visual_landmarks = static_cast<uint64_t>(visual.landmarks);
    summary.camera_standstill_frames = static_cast<uint64_t>(visual.standstill_frames);
    summary.visual_loop_closures = static_cast<uint64_t>(visual.loop_closures);
    if (!visual_loops_.empty()) summary.visual_loop_closures = 0;
    for (const auto& loops : visual_loops_) {
      summary.visual_loop_closures += static_cast<uint64_t>(loops->loops());
      summary.loop_candidates += static_cast<uint64_t>(loops->candidates_checked());
    }
    summary.visual_scale_free = visual.scale_free;
    summary.camera_features = visual.features;
    summary.camera_feature_ms = visual.feature_frames > 0 ? 1000.0 * visual.feature_seconds / visual.feature_frames : 0.0;
    summary.camera_mapping_ms = visual.keyframes > 0 ? 1000.0 * visual.mapping_seconds / visual.keyframes : 0.0;
    summary.camera_learned_matcher = visual.learned_matcher;
    summary.visual_place_recognition = visual.place_recognition;
    const CameraOdometry::ImageConditionCounts& conditions = camera_odometry_->image_conditions();
    summary.camera_dark_frames = conditions.dark;
    summary.camera_glare_frames = conditions.glare;
    summary.camera_motion_blur_frames = conditions.motion_blur;
  }
  if (splats_) {
    const SessionSplatsSummary splats = splats_->summary();
    summary.splat_views = splats.views;
    summary.splat_iterations = splats.iterations;
    summary.splat_gaussians = splats.gaussians;
    summary.splat_images_skipped = splats.images_skipped;
  }
  summary.map_memory_bytes = map_builder_.memory_bytes();
  if (map_builder_.point_map()) summary.map_points_moving_removed = map_builder_.point_map()->moving_points_removed();
  return summary;
}

std::optional<SE3> Session::keyframe_pose(uint64_t keyframe_id) const { return graph().optimized_pose(keyframe_id); }

std::vector<StampedPose> Session::optimized_trajectory() const {
  if (planar_) {
    // The body at every scan on the planar graph.
    std::vector<StampedPose> trajectory;
    for (const auto& [time, T_world_laser] : planar_->trajectory()) trajectory.push_back({time, T_world_laser * T_body_lidar_.inverse()});
    return trajectory;
  }
  // The correction D = X_optimized * T_uncorrected^-1 of every keyframe the graph knows.
  std::vector<std::pair<Timestamp, SE3>> corrections;
  for (const KeyframeRecord& keyframe : keyframe_records_) {
    if (const std::optional<SE3> optimized = graph().optimized_pose(keyframe.keyframe_id)) {
      corrections.emplace_back(keyframe.timestamp, *optimized * keyframe.T_world_body_uncorrected.inverse());
    }
  }
  // Before the first keyframe (a start whose heading the GNSS track gave later): from the
  // Frontend's world correction of that time (it turned the track before the alignment about
  // its start), moved by the graph's shift of the first keyframe, at the first pose, to the
  // first keyframe's correction, which applied alone would swing the whole stretch about the
  // keyframe with any rotation the graph adds.
  if (!corrections.empty() && !uncorrected_poses_.empty() && uncorrected_poses_.front().timestamp < corrections.front().first) {
    const auto first = std::find_if(keyframe_records_.begin(), keyframe_records_.end(), [&](const KeyframeRecord& keyframe) {
      return keyframe.timestamp == corrections.front().first;
    });
    const SE3 T_world_first = first->world_correction * first->T_world_body_uncorrected;  // the Frontend's keyframe
    const Eigen::Vector3d shift = (corrections.front().second * first->T_world_body_uncorrected).translation() - T_world_first.translation();
    corrections.insert(corrections.begin(), {uncorrected_poses_.front().timestamp, SE3(SO3(), shift) * first->world_correction});
  }
  std::vector<StampedPose> trajectory;
  trajectory.reserve(uncorrected_poses_.size());
  std::size_t next = 0;  // the first keyframe after the pose
  for (const StampedPose& pose : uncorrected_poses_) {
    while (next < corrections.size() && corrections[next].first <= pose.timestamp) ++next;
    SE3 correction = frontend_->world_correction();  // no keyframe in the graph: the filter's own
    if (!corrections.empty()) {
      if (next == 0) {
        correction = corrections.front().second;
      } else if (next == corrections.size()) {
        correction = corrections.back().second;
      } else {
        const auto& [t0, D0] = corrections[next - 1];
        const auto& [t1, D1] = corrections[next];
        const double fraction = (pose.timestamp - t0).seconds() / (t1 - t0).seconds();
        correction = D0 * SE3::exp(fraction * (D0.inverse() * D1).log());
      }
    }
    trajectory.push_back({pose.timestamp, correction * pose.T_world_body});
  }
  return trajectory;
}

}  // namespace hanzo::fusion::pipeline
