#pragma once
// PlanarLaserOdometry: a 2D laser scanner (a lidar sensor with `type: planar_laser` in the
// fusion configuration) coupled to a Frontend, as LidarInertialOdometry couples a 3D LiDAR.
// Per scan:
//  1. the odometry: with an IMU, the Frontend's motion since the previous scan, taken from the
//     filter's pose after the previous scan was fused (so that the laser's own corrections are
//     not counted as motion again); without one, the wheels' own dead reckoning when wheel
//     messages come in (add_wheels: as a 2D SLAM uses odometry; the motion model cannot follow
//     a turn faster than its angular_acceleration_noise allows), else the motion model's;
//  2. the scan is deskewed with the filter's motion during it (per-point times), then
//     PlanarLaserSlam (planar_laser_slam.hpp) matches it against its local map, makes
//     keyframes and closes loops;
//  3. the matched pose goes back into the Frontend as a pose measurement of the laser
//     (Frontend::push_pose): x, y and yaw with the matcher's covariance (floored at
//     position_sigma_floor / yaw_sigma_floor); z, roll and pitch stay the filter's (sigmas of
//     10 m and 1 rad: the laser does not see them). After a loop closure the estimate jumps to
//     the optimized graph: the Frontend is moved by that jump (world frame, about z) through
//     the `correct` callback the owner gives (the Session corrects its newest keyframe).
// Frames: the map is the Frontend's world (the first scan is placed at the Frontend's pose);
// T_world_laser of a scan is the filter's pose moved in x, y, yaw onto the SLAM estimate.
// Failure cases: a scan the Frontend has no pose for (before initialization, outside its
// history), or one PlanarLaserSlam refuses (time not increasing, too few points, non-finite):
// an Error that says so, nothing changes.

#include <deque>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se2.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/maps/map_builder.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/pipeline/frontend.hpp"
#include "hanzo/fusion/pipeline/planar_laser_slam.hpp"

namespace hanzo::fusion::pipeline {

struct PlanarLaserOdometryConfig {
  PlanarLaserSlamConfig slam;
  /// Floors of the pose measurement's sigmas (the matcher's covariance treats every beam as
  /// independent and is optimistic).
  double position_sigma_floor = 0.03;  ///< m
  double yaw_sigma_floor = 0.01;       ///< rad

  Status validate() const;
};

/// The planar (x, y, yaw) part of a pose, and a planar motion as a 3D one (about z).
SE2 planar_part(const SE3& pose);
SE3 lifted(const SE2& motion);

class PlanarLaserOdometry {
 public:
  /// Moves the Frontend's estimate by T_world_corrected_world (world frame).
  using CorrectFrontend = std::function<void(const SE3& T_world_correction)>;

  /// laser_time_offset: the calibration's (t_body = t_laser + offset); scans come in the body clock.
  PlanarLaserOdometry(Frontend& frontend, std::string laser_sensor, const SE3& T_body_laser, Duration laser_time_offset,
                      PlanarLaserOdometryConfig config, CorrectFrontend correct);

  struct Outcome {
    PlanarScanEstimate estimate;
    SE3 T_world_laser;  ///< after the scan (and any loop closure it made)
  };
  /// Wheel odometry (body clock), dead-reckoned for the scans' odometry when the Frontend has
  /// no IMU. T_body_wheels: the wheels' mounting. Messages out of time order are ignored.
  void add_wheels(const msgs::WheelOdometryMessage& wheels, Timestamp body_time, const SE3& T_body_wheels);
  /// Matches one scan (its timestamp in the body clock) and fuses its pose into the Frontend.
  Result<Outcome> add_scan(const msgs::PointCloudMessage& scan);
  /// Optimizes the whole graph to convergence (a replay's end).
  Status finish();

  const PlanarLaserSlam& slam() const { return slam_; }
  /// Every scan's T_world_laser on the graph's current estimate.
  std::vector<std::pair<Timestamp, SE3>> trajectory() const;
  /// The map's layers from the keyframes at their optimized poses: `map_config`'s occupancy
  /// (every keyframe ray cast) and point layers.
  Result<msgs::FusionMap> map(const maps::MapBuilderConfig& map_config) const;

 private:
  /// The scan's points moved into the laser frame at its timestamp by the filter's motion
  /// during the scan (per-point times); as measured without them.
  msgs::PointCloudMessage deskewed(const msgs::PointCloudMessage& scan, const SE3& T_world_laser_stamp) const;
  /// A keyframe's planar pose as T_world_laser at the laser's height, level.
  SE3 world_laser(const SE2& planar) const;

  Frontend& frontend_;
  std::string laser_sensor_;
  SE3 T_body_laser_;
  Duration laser_time_offset_;
  PlanarLaserOdometryConfig config_;
  CorrectFrontend correct_;
  PlanarLaserSlam slam_;
  std::optional<SE2> T_odom_last_;         ///< the odometry handed to the SLAM for the previous scan
  std::optional<SE2> T_world_laser_after_; ///< the filter's planar pose at the previous scan, after it was fused
  std::optional<Timestamp> last_time_;
  /// Wheel dead reckoning: T_odom_laser by time (the last few seconds), and the previous message.
  std::deque<std::pair<Timestamp, SE2>> wheel_odometry_;
  std::optional<msgs::WheelOdometryMessage> previous_wheels_;
  std::optional<SE2> last_wheels_;  ///< the dead reckoning at the previous scan (none: it did not cover it)
  /// The wheel odometry's T_odom_laser at `time`, interpolated; none outside what it covers.
  std::optional<SE2> wheel_odometry_at(Timestamp time) const;
  double laser_height_ = 0.0;              ///< m: z of the laser in the world at the first scan (map keyframes)
};

}  // namespace hanzo::fusion::pipeline
