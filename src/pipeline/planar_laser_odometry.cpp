#include "hanzo/fusion/pipeline/planar_laser_odometry.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::pipeline {

Status PlanarLaserOdometryConfig::validate() const {
  HANZO_RETURN_IF_ERROR(slam.validate());
  if (!(position_sigma_floor > 0) || !(yaw_sigma_floor > 0)) {
    return Error("planar laser odometry: position_sigma_floor and yaw_sigma_floor must be > 0");
  }
  return ok_status();
}

SE2 planar_part(const SE3& pose) {
  const Eigen::Matrix3d rotation = pose.rotation().matrix();
  return SE2(std::atan2(rotation(1, 0), rotation(0, 0)), pose.translation().head<2>());
}

SE3 lifted(const SE2& motion) {
  return SE3(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), motion.angle()), Eigen::Vector3d(motion.translation().x(), motion.translation().y(), 0.0));
}

PlanarLaserOdometry::PlanarLaserOdometry(Frontend& frontend, std::string laser_sensor, const SE3& T_body_laser, Duration laser_time_offset,
                                         PlanarLaserOdometryConfig config, CorrectFrontend correct)
    : frontend_(frontend),
      laser_sensor_(std::move(laser_sensor)),
      T_body_laser_(T_body_laser),
      laser_time_offset_(laser_time_offset),
      config_(std::move(config)),
      correct_(std::move(correct)),
      slam_(config_.slam) {}

SE3 PlanarLaserOdometry::world_laser(const SE2& planar) const {
  SE3 pose = lifted(planar);
  return SE3(pose.rotation(), Eigen::Vector3d(pose.translation().x(), pose.translation().y(), laser_height_));
}

void PlanarLaserOdometry::add_wheels(const msgs::WheelOdometryMessage& wheels, Timestamp body_time, const SE3& T_body_wheels) {
  constexpr double kHistory = 10.0;  // s of dead reckoning kept
  if (!wheel_odometry_.empty() && body_time <= wheel_odometry_.back().first) return;
  if (!(wheels.wheel_separation > 0) || !std::isfinite(wheels.left_distance) || !std::isfinite(wheels.right_distance)) return;
  const SE2 T_wheels_laser = planar_part(T_body_wheels.inverse() * T_body_laser_);
  SE2 T_odom_wheels = wheel_odometry_.empty() ? SE2() : wheel_odometry_.back().second * T_wheels_laser.inverse();
  if (previous_wheels_) {
    // Differential drive over the interval: the arc's chord at half the turn.
    const double left = wheels.left_distance - previous_wheels_->left_distance;
    const double right = wheels.right_distance - previous_wheels_->right_distance;
    const double distance = 0.5 * (left + right), turn = (right - left) / wheels.wheel_separation;
    T_odom_wheels = T_odom_wheels * SE2(turn, Eigen::Vector2d(distance * std::cos(0.5 * turn), distance * std::sin(0.5 * turn)));
  }
  previous_wheels_ = wheels;
  wheel_odometry_.emplace_back(body_time, T_odom_wheels * T_wheels_laser);
  while (wheel_odometry_.size() > 2 && (body_time - wheel_odometry_.front().first).seconds() > kHistory) wheel_odometry_.pop_front();
}

std::optional<SE2> PlanarLaserOdometry::wheel_odometry_at(Timestamp time) const {
  // A scan may arrive before the wheel message after it: the last interval's motion carries
  // the dead reckoning on for up to this long.
  constexpr double kMaxExtrapolation = 0.25;  // s
  if (wheel_odometry_.size() < 2 || time < wheel_odometry_.front().first) return std::nullopt;
  if (time > wheel_odometry_.back().first) {
    const auto& [t1, pose1] = wheel_odometry_.back();
    const auto& [t0, pose0] = *std::prev(wheel_odometry_.end(), 2);
    if ((time - t1).seconds() > kMaxExtrapolation) return std::nullopt;
    return pose1 * SE2::exp((pose0.inverse() * pose1).log() * ((time - t1).seconds() / (t1 - t0).seconds()));
  }
  const auto after = std::lower_bound(wheel_odometry_.begin(), wheel_odometry_.end(), time,
                                      [](const std::pair<Timestamp, SE2>& entry, Timestamp t) { return entry.first < t; });
  if (after == wheel_odometry_.begin()) return after->second;
  const auto before = std::prev(after);
  const double fraction = (time - before->first).seconds() / (after->first - before->first).seconds();
  return SE2::interpolate(before->second, after->second, fraction);
}

Result<PlanarLaserOdometry::Outcome> PlanarLaserOdometry::add_scan(const msgs::PointCloudMessage& scan) {
  const std::optional<SE3> T_world_body = frontend_.pose_at(scan.timestamp);
  if (!T_world_body) {
    return Error(fmt::format("planar laser: the filter has no pose at {:.6f} s (not initialized, or outside its history)", scan.timestamp.seconds()));
  }
  const SE3 T_world_laser_before = *T_world_body * T_body_laser_;
  const SE2 planar_before = planar_part(T_world_laser_before);
  // The odometry: without an IMU the wheels' dead reckoning when it covers the scan; else the
  // filter's motion since the previous scan was fused (its own correction left out), chained
  // onto the odometry given for that scan. The first scan is placed at the filter's pose.
  const std::optional<SE2> wheels = frontend_.has_imu() ? std::nullopt : wheel_odometry_at(scan.timestamp);
  SE2 T_odom_laser = planar_before;
  if (T_odom_last_ && wheels && last_wheels_) {
    T_odom_laser = *T_odom_last_ * (last_wheels_->inverse() * *wheels);
  } else if (T_odom_last_) {
    T_odom_laser = *T_odom_last_ * (T_world_laser_after_->inverse() * planar_before);
  }
  last_wheels_ = wheels;
  PlanarScanEstimate estimate;
  HANZO_ASSIGN_OR_RETURN(estimate, slam_.add_scan(deskewed(scan, T_world_laser_before), T_odom_laser));
  if (!last_time_) laser_height_ = T_world_laser_before.translation().z();
  T_odom_last_ = T_odom_laser;
  last_time_ = scan.timestamp;

  // The match as a measurement: the filter's pose moved in x, y, yaw onto it.
  const SE3 T_world_laser_matched = lifted(estimate.T_map_laser_matched * planar_before.inverse()) * T_world_laser_before;
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  covariance.topLeftCorner<2, 2>() = estimate.covariance.topLeftCorner<2, 2>();
  covariance.topLeftCorner<2, 2>().diagonal().array() += config_.position_sigma_floor * config_.position_sigma_floor;
  covariance(2, 2) = 100.0;                                  // z: 10 m, the laser does not see it
  covariance(3, 3) = covariance(4, 4) = 1.0;                 // roll, pitch: 1 rad
  covariance(5, 5) = estimate.covariance(2, 2) + config_.yaw_sigma_floor * config_.yaw_sigma_floor;
  if (estimate.scan_matched) {
    if (PushStatus fused = frontend_.push_pose(laser_sensor_, scan.timestamp - laser_time_offset_, T_world_laser_matched, covariance); !fused) {
      logger()->debug("planar laser: the scan at {:.3f} s was not fused: {}", scan.timestamp.seconds(), fused.error().message);
    }
  }
  // Without an IMU a measurement at the filter's newest time waits for the next message: move
  // the motion model just past it so that it is fused now (and pose_at below sees it).
  if (!frontend_.has_imu()) frontend_.propagate_to(scan.timestamp + Duration::from_nanoseconds(1));
  // A loop closure moved the graph: the Frontend jumps with it.
  if (estimate.loop_closures_added > 0 && correct_) correct_(lifted(estimate.T_map_laser * estimate.T_map_laser_matched.inverse()));
  // Just after the update (the filter's state at the scan's own time is the one before it).
  const std::optional<SE3> after = frontend_.pose_at(scan.timestamp + Duration::from_nanoseconds(1));
  T_world_laser_after_ = planar_part((after ? *after : *T_world_body) * T_body_laser_);
  Outcome outcome;
  outcome.estimate = estimate;
  outcome.T_world_laser = lifted(estimate.T_map_laser * planar_before.inverse()) * T_world_laser_before;
  return outcome;
}

msgs::PointCloudMessage PlanarLaserOdometry::deskewed(const msgs::PointCloudMessage& scan, const SE3& T_world_laser_stamp) const {
  if (scan.point_timestamps.size() != scan.points.size() || scan.points.empty()) return scan;
  // The laser's pose every kDeskewStep over the scan's point times, interpolated per point.
  constexpr double kDeskewStep = 0.01;  // s
  const auto [first, last] = std::minmax_element(scan.point_timestamps.begin(), scan.point_timestamps.end());
  const int samples = std::max(1, static_cast<int>(std::ceil((*last - *first).seconds() / kDeskewStep)));
  std::vector<SE3> T_stamp_laser(static_cast<std::size_t>(samples) + 1);
  for (int i = 0; i <= samples; ++i) {
    const Timestamp time = *first + Duration::from_seconds((*last - *first).seconds() * i / samples);
    const std::optional<SE3> T_world_body = frontend_.pose_at(time);
    if (!T_world_body) return scan;  // outside the filter's history: as measured
    T_stamp_laser[static_cast<std::size_t>(i)] = T_world_laser_stamp.inverse() * *T_world_body * T_body_laser_;
  }
  msgs::PointCloudMessage out = scan;
  const double span = std::max(1e-9, (*last - *first).seconds());
  for (std::size_t k = 0; k < scan.points.size(); ++k) {
    const double position = (scan.point_timestamps[k] - *first).seconds() / span * samples;
    const int i = std::min(samples - 1, static_cast<int>(position));
    const SE3 pose = SE3::interpolate(T_stamp_laser[static_cast<std::size_t>(i)], T_stamp_laser[static_cast<std::size_t>(i) + 1], position - i);
    out.points[k] = (pose * scan.points[k].cast<double>()).cast<float>();
    out.points[k].z() = 0.0F;  // the scan plane
  }
  return out;
}

Status PlanarLaserOdometry::finish() { return slam_.finish(); }

std::vector<std::pair<Timestamp, SE3>> PlanarLaserOdometry::trajectory() const {
  const io::Trajectory trajectory = slam_.trajectory();
  std::vector<std::pair<Timestamp, SE3>> poses;
  poses.reserve(trajectory.size());
  for (std::size_t i = 0; i < trajectory.size(); ++i) poses.emplace_back(trajectory.timestamps[i], world_laser(io::planar_pose(trajectory.poses[i])));
  return poses;
}

Result<msgs::FusionMap> PlanarLaserOdometry::map(const maps::MapBuilderConfig& map_config) const {
  Result<maps::MapBuilder> created = maps::MapBuilder::create(map_config);
  if (!created) return created.error();
  maps::MapBuilder& builder = *created;
  for (std::size_t k = 0; k < slam_.keyframe_count(); ++k) {
    cloud::PointCloud points;
    for (const Eigen::Vector2d& point : slam_.keyframe_points(k)) points.positions.emplace_back(point.cast<float>().x(), point.cast<float>().y(), 0.0F);
    HANZO_RETURN_IF_ERROR(builder.insert(world_laser(slam_.keyframe_pose(k)), points));
  }
  msgs::FusionMap map;
  builder.write_layers(map);
  return map;
}

}  // namespace hanzo::fusion::pipeline
