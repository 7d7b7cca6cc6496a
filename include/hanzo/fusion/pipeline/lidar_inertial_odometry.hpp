#pragma once
// LidarInertialOdometry: LiDAR odometry (lidar/lidar_odometry.hpp) coupled to a Frontend's
// IMU-driven filter (loosely coupled, as LIO-SAM's front end): per scan,
//  1. the prediction is the motion of the Frontend's pose (Frontend::pose_at, the
//     IMU-propagated filter, times T_body_lidar) between the previous and this sweep's
//     middles. The sweep is deskewed with the filter's poses sampled every
//     deskew_sample_interval during the sweep (the IMU's motion, accelerations and changing
//     turn rates included), not with a constant-velocity guess;
//  2. the scan is registered to the local map from that prediction (LidarOdometry);
//  3. the result goes back into the filter as a pose of the LiDAR sensor in the odometry's map
//     (Frontend::push_map_pose: the map frame's pose in the world is estimated with the state,
//     so the map's tilt from the start's alignment is levelled and GNSS can move the map) with
//     the registration covariance, floored at
//     position_sigma_floor / rotation_sigma_floor (the registration's own covariance treats
//     thousands of points as independent and is far too small). Along degenerate directions
//     (a corridor's axis) the covariance is large, so the filter keeps its IMU (and wheel)
//     estimate there.
// The odometry's frame starts at the Frontend's pose at the first scan.
// A scan that arrives before the Frontend is initialized or outside its history (older than
// the lag window, newer than the last fused IMU sample) is refused with an Error that says so;
// nothing changes then. Corrections applied to the Frontend (Frontend::apply_correction, by a
// backend after a loop closure) move the map frame with the Frontend's world: the local map
// stays as it is (it is local) and the scans' world poses follow the corrected world.

#include <cstddef>
#include <memory>
#include <optional>
#include <string>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/lidar/lidar_odometry.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/pipeline/frontend.hpp"

namespace hanzo::fusion::pipeline {

struct LidarInertialOdometryConfig {
  lidar::LidarOdometryConfig odometry;
  /// Added to the registration covariance. 2 cm / 0.002 rad made the filter so confident that
  /// the IMU's model error in turns got LiDAR updates gated and the filter diverged (urban
  /// scenario: 57 of 390 gated, 0.30 % drift); 5 cm / 0.005 rad fuse them all (0.09 %).
  double position_sigma_floor = 0.05;   ///< m
  double rotation_sigma_floor = 0.005;  ///< rad
  /// A sweep flagged weather_degraded (rain, fog: LidarOdometryConfig) is fused with its
  /// covariance times this (sigmas x2 by default).
  double weather_covariance_scale = 4.0;
  /// Deskew with the filter's poses during the sweep when an IMU propagates the filter (false,
  /// or without an IMU: the odometry's constant twist, which follows the registration, as
  /// LiDAR-only odometry). The filter's poses are its estimates at those times, so an update
  /// fused inside a sweep (a GNSS fix) shows as a small step there.
  bool imu_deskew = true;
  /// Fuse the registered poses in the odometry's map frame, whose pose in the world the filter
  /// estimates (true), or as world poses with the map fixed where the first scan put it (false).
  /// Fixed, a start tilted by the accelerometer bias (about 0.5 degrees for 0.08 m/s^2) or a first
  /// GNSS fix off by a metre stays in every pose; estimated, the real-time poses are levelled and
  /// moved onto the GNSS world as those become observable (a turn, the fixes), and the poses before
  /// carry the correction as a change: segments across it drift more (measured in
  /// bench/RESULTS.md). The Session estimates it when GNSS defines the world.
  bool estimate_map_frame = false;
  double deskew_sample_interval = 0.005;  ///< s between the filter poses sampled (an IMU period at 200 Hz); <= 0: constant twist
};

struct LidarInertialOdometryStatistics {
  std::size_t scans = 0;       ///< registered
  std::size_t refused = 0;     ///< refused scans (Frontend not ready, bad scan, registration failure)
  std::size_t fused = 0;       ///< pose measurements the Frontend accepted
  std::size_t degenerate = 0;  ///< registered scans flagged degenerate
  std::size_t weather_degraded = 0;  ///< registered scans flagged weather_degraded (fused with less weight)
  std::size_t imu_deskewed = 0;      ///< prepared sweeps deskewed with the filter's poses (the others: constant twist)
};

class LidarInertialOdometry {
 public:
  /// `frontend` must outlive this object; `lidar_sensor` names the Frontend's LiDAR sensor and
  /// T_body_lidar is its calibration.
  /// lidar_time_offset: the LiDAR's calibrated offset (t_body = t_lidar + offset); sweeps come
  /// to prepare() / process() in the body clock already, and their poses go to the Frontend in
  /// the LiDAR's clock (Frontend::push_pose applies the offset).
  LidarInertialOdometry(Frontend& frontend, std::string lidar_sensor, const SE3& T_body_lidar,
                        LidarInertialOdometryConfig config = {}, Duration lidar_time_offset = {});

  /// Registers one sweep (its times in the body clock) and
  /// fuses the result. Push the IMU messages up to the end of the sweep into the Frontend first.
  /// = fuse(register_scan(prepare(scan))).
  Result<lidar::LidarOdometryEstimate> process(const msgs::PointCloudMessage& scan);

  /// The three steps of process(), for callers that register on another thread (the server:
  /// the IMU's poses then never wait for a registration). prepare() and fuse() use the Frontend
  /// (call them where the Frontend is used); register_scan() touches only the odometry (one call
  /// at a time, in the order of prepare(); no Frontend access), so it may run elsewhere. fuse()
  /// of a sweep registered late pushes a pose in the past: the Frontend fuses it by rolling
  /// back, if it is still within its lag window.
  struct PreparedScan {
    Timestamp time;                 ///< the sweep's timestamp (its start)
    cloud::PointCloud cloud;
    SE3 T_world_lidar_filter;       ///< the filter's pose at the middle of the sweep
    SE3 world_correction;           ///< Frontend::world_correction() then
    /// T_middle_lidar during the sweep from the filter (imu_deskew; none for sweeps without
    /// point times or when the filter lacks a pose inside the sweep).
    std::optional<lidar::SweepMotion> sweep_motion;
  };
  struct RegisteredScan {
    lidar::LidarOdometryEstimate estimate;  ///< in the odometry's frame
    SE3 T_world_lidar;                      ///< in the session's world (after fuse(): the filter's map frame)
    /// of the pose measurement (floors, weather included), over (position in the odometry's
    /// axes, rotation sensor frame)
    Eigen::Matrix<double, 6, 6> covariance;
    std::vector<Eigen::Vector3f> points;    ///< the deskewed sweep (sensor frame), for maps
    double seconds = 0.0;                   ///< time the registration took
  };
  Result<PreparedScan> prepare(const msgs::PointCloudMessage& scan);
  Result<RegisteredScan> register_scan(const PreparedScan& scan);
  /// Counts the outcome and fuses a registered sweep; returns it, or the error (registration
  /// failure, or the Frontend refusing the pose).
  Result<RegisteredScan> fuse(Result<RegisteredScan> registered);

  /// With estimate_map_frame: from the next fused sweep on, the map frame stays where the
  /// filter has it now and moves only with the Frontend's world corrections; sweeps are fused
  /// as world poses. For a session whose backend holds the world (GNSS in the keyframe graph,
  /// the Frontend following it): the filter then has no absolute measurement, and an estimated
  /// map frame would take up the IMU's drift instead of the body. Call from fuse()'s thread.
  void hold_map_frame() { hold_map_frame_ = true; }
  /// Sweeps seen before (sensor-frame points at their world poses, e.g. a restarted session's
  /// stored keyframes) that the odometry's local map starts with, so that the first sweeps
  /// register against them. Before the first sweep only (later: ignored).
  struct SeedKeyframe {
    SE3 T_world_lidar;
    std::vector<Eigen::Vector3f> points;
  };
  void seed_map(std::vector<SeedKeyframe> keyframes) { seed_ = std::move(keyframes); }
  bool map_frame_held() const { return held_map_frame_.has_value(); }
  const LidarInertialOdometryStatistics& statistics() const { return statistics_; }
  /// The odometry (its local map, latest pose); nullptr before the first scan. Not while
  /// register_scan() runs on another thread.
  const lidar::LidarOdometry* odometry() const { return odometry_.get(); }

 private:
  /// T_middle_lidar every deskew_sample_interval over [0, sweep_length] s after scan_time from
  /// Frontend::pose_at; none when the filter lacks a pose there.
  std::optional<lidar::SweepMotion> sample_sweep_motion(Timestamp scan_time, double sweep_length,
                                                        const SE3& T_world_lidar_middle) const;

  Frontend& frontend_;
  std::vector<SeedKeyframe> seed_;
  std::string lidar_sensor_;
  SE3 T_body_lidar_;
  LidarInertialOdometryConfig config_;
  Duration lidar_time_offset_;
  std::unique_ptr<lidar::LidarOdometry> odometry_;
  // register_scan()'s state:
  std::optional<SE3> last_filter_pose_;  ///< the filter's T_world_lidar at the last registered sweep
  SE3 T_world_odometry_;                 ///< the odometry's frame in the session's (corrected) world
  SE3 correction_at_last_scan_;          ///< Frontend::world_correction() then
  LidarInertialOdometryStatistics statistics_;
  // fuse()'s state (hold_map_frame): the held map frame in the world of `correction`.
  struct HeldMapFrame {
    SE3 T_world_map;
    SE3 correction;
  };
  bool hold_map_frame_ = false;
  std::optional<HeldMapFrame> held_map_frame_;
};

}  // namespace hanzo::fusion::pipeline
