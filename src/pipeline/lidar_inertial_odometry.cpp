#include "hanzo/fusion/pipeline/lidar_inertial_odometry.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::pipeline {

LidarInertialOdometry::LidarInertialOdometry(Frontend& frontend, std::string lidar_sensor, const SE3& T_body_lidar,
                                             LidarInertialOdometryConfig config, Duration lidar_time_offset)
    : frontend_(frontend),
      lidar_sensor_(std::move(lidar_sensor)),
      T_body_lidar_(T_body_lidar),
      config_(std::move(config)),
      lidar_time_offset_(lidar_time_offset) {}

Result<lidar::LidarOdometryEstimate> LidarInertialOdometry::process(const msgs::PointCloudMessage& scan) {
  PreparedScan prepared;
  HANZO_ASSIGN_OR_RETURN(prepared, prepare(scan));
  RegisteredScan registered;
  HANZO_ASSIGN_OR_RETURN(registered, fuse(register_scan(prepared)));
  return std::move(registered.estimate);
}

Result<LidarInertialOdometry::PreparedScan> LidarInertialOdometry::prepare(const msgs::PointCloudMessage& scan) {
  auto refuse = [this](const std::string& reason) -> Error {
    ++statistics_.refused;
    return Error(fmt::format("lidar-inertial odometry ({}): {}", lidar_sensor_, reason));
  };
  PreparedScan prepared;
  prepared.time = scan.timestamp;
  Result<cloud::PointCloud> cloud = cloud::from_message(scan);
  if (!cloud) return refuse(cloud.error().message);
  prepared.cloud = std::move(cloud).value();
  const std::vector<float>& times = prepared.cloud.times;
  const double middle = prepared.cloud.has_times() ? 0.5 * static_cast<double>(*std::max_element(times.begin(), times.end())) : 0.0;
  const Timestamp middle_time = scan.timestamp + Duration::from_seconds(middle);
  const std::optional<SE3> T_world_body = frontend_.pose_at(middle_time);
  if (!T_world_body) {
    return refuse(fmt::format("no filter pose at {:.6f} s (the session is not initialized, or the IMU has not reached the "
                              "sweep yet, or the sweep is older than the lag window)", middle_time.seconds()));
  }
  prepared.T_world_lidar_filter = *T_world_body * T_body_lidar_;
  prepared.world_correction = frontend_.world_correction();
  // Without an IMU the filter's motion over the sweep is the motion model's extrapolation: the
  // odometry's own constant twist, which follows the registration, deskews better.
  if (config_.imu_deskew && frontend_.has_imu() && prepared.cloud.has_times()) {
    prepared.sweep_motion = sample_sweep_motion(scan.timestamp, 2.0 * middle, prepared.T_world_lidar_filter);
    if (prepared.sweep_motion) ++statistics_.imu_deskewed;
  }
  return prepared;
}

std::optional<lidar::SweepMotion> LidarInertialOdometry::sample_sweep_motion(Timestamp scan_time, double sweep_length,
                                                                              const SE3& T_world_lidar_middle) const {
  if (!(config_.deskew_sample_interval > 0) || !(sweep_length > 0)) return std::nullopt;
  const SE3 T_middle_world = T_world_lidar_middle.inverse();
  const auto samples = static_cast<std::size_t>(std::ceil(sweep_length / config_.deskew_sample_interval));
  std::vector<double> times;
  std::vector<SE3> poses;
  times.reserve(samples + 1);
  poses.reserve(samples + 1);
  for (std::size_t i = 0; i <= samples; ++i) {
    const double t = std::min(static_cast<double>(i) * config_.deskew_sample_interval, sweep_length);
    if (!times.empty() && t <= times.back()) break;
    const std::optional<SE3> T_world_body = frontend_.pose_at(scan_time + Duration::from_seconds(t));
    if (!T_world_body) return std::nullopt;  // the filter does not cover the sweep: constant twist
    times.push_back(t);
    poses.push_back(T_middle_world * *T_world_body * T_body_lidar_);
  }
  Result<lidar::SweepMotion> motion = lidar::SweepMotion::from_samples(std::move(times), poses);
  if (!motion) return std::nullopt;
  return std::move(motion).value();
}

Result<LidarInertialOdometry::RegisteredScan> LidarInertialOdometry::register_scan(const PreparedScan& scan) {
  const auto started = std::chrono::steady_clock::now();
  const SE3& T_world_lidar = scan.T_world_lidar_filter;
  // Backend corrections since the previous sweep moved the session's world: follow them.
  if (!odometry_) correction_at_last_scan_ = scan.world_correction;  // the odometry starts in today's world
  const SE3 correction_since = scan.world_correction * correction_at_last_scan_.inverse();
  if (last_filter_pose_) last_filter_pose_ = correction_since * *last_filter_pose_;
  T_world_odometry_ = correction_since * T_world_odometry_;
  correction_at_last_scan_ = scan.world_correction;
  if (!odometry_) {
    odometry_ = std::make_unique<lidar::LidarOdometry>(config_.odometry, T_world_lidar);
    for (const SeedKeyframe& keyframe : seed_) {  // at creation the odometry's frame is the world
      cloud::PointCloud cloud;
      cloud.positions = keyframe.points;
      odometry_->add_map_points(cloud::transformed(cloud, keyframe.T_world_lidar).positions, keyframe.T_world_lidar.translation());
    }
    seed_.clear();
  }
  // The filter's motion since the previous sweep (not its absolute pose: where the filter and
  // the odometry disagree, e.g. after a gated update, the motion is still right).
  std::optional<SE3> motion;
  if (last_filter_pose_) motion = last_filter_pose_->inverse() * T_world_lidar;
  RegisteredScan registered;
  HANZO_ASSIGN_OR_RETURN(registered.estimate,
                         with_context(odometry_->add_scan(scan.time, scan.cloud, motion, scan.sweep_motion), "lidar-inertial odometry (" + lidar_sensor_ + ")"));
  last_filter_pose_ = T_world_lidar;
  registered.T_world_lidar = T_world_odometry_ * registered.estimate.T_world_lidar;
  // Covariance over (position in the odometry's axes, rotation in the sensor frame): the
  // tangent's translation rho is in the sensor frame (right perturbation), so position = R rho.
  Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Identity();
  J.topLeftCorner<3, 3>() = registered.estimate.T_world_lidar.rotation().matrix();
  Eigen::Matrix<double, 6, 6> covariance = J * registered.estimate.covariance * J.transpose();
  covariance = 0.5 * (covariance + covariance.transpose());
  covariance.diagonal().head<3>().array() += config_.position_sigma_floor * config_.position_sigma_floor;
  covariance.diagonal().tail<3>().array() += config_.rotation_sigma_floor * config_.rotation_sigma_floor;
  if (registered.estimate.weather_degraded) covariance *= config_.weather_covariance_scale;
  registered.covariance = covariance;
  registered.points = odometry_->last_scan_points();
  registered.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  return registered;
}

Result<LidarInertialOdometry::RegisteredScan> LidarInertialOdometry::fuse(Result<RegisteredScan> registered) {
  if (!registered) {
    ++statistics_.refused;
    return registered.error();
  }
  const lidar::LidarOdometryEstimate& estimate = registered->estimate;
  ++statistics_.scans;
  statistics_.degenerate += estimate.degenerate ? 1 : 0;
  statistics_.weather_degraded += estimate.weather_degraded ? 1 : 0;
  const Timestamp sensor_time = estimate.time - lidar_time_offset_;
  if (config_.estimate_map_frame && hold_map_frame_ && !held_map_frame_) {
    if (const std::optional<SE3> T_world_map = frontend_.map_frame(lidar_sensor_)) held_map_frame_ = HeldMapFrame{*T_world_map, frontend_.world_correction()};
  }
  if (held_map_frame_) {
    // Backend corrections since the last sweep moved the world: the held frame moves with it.
    held_map_frame_->T_world_map = frontend_.world_correction() * held_map_frame_->correction.inverse() * held_map_frame_->T_world_map;
    held_map_frame_->correction = frontend_.world_correction();
    registered->T_world_lidar = held_map_frame_->T_world_map * estimate.T_world_lidar;
  }
  Status fused;
  if (config_.estimate_map_frame && !held_map_frame_) {
    fused = frontend_.push_map_pose(lidar_sensor_, sensor_time, estimate.T_world_lidar, registered->covariance);
  } else {
    // The covariance's position block from the odometry's axes to the world's.
    const SE3& T_world_odometry = held_map_frame_ ? held_map_frame_->T_world_map : T_world_odometry_;
    Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Identity();
    J.topLeftCorner<3, 3>() = T_world_odometry.rotation().matrix();
    fused = frontend_.push_pose(lidar_sensor_, sensor_time, registered->T_world_lidar, J * registered->covariance * J.transpose());
  }
  if (!fused) {
    return Error(fmt::format("lidar-inertial odometry ({}): registered, but the frontend refused the pose: {}", lidar_sensor_,
                             fused.error().message));
  }
  ++statistics_.fused;
  // The map frame as the filter estimates it now (none yet when the pose waits for the IMU).
  if (config_.estimate_map_frame && !held_map_frame_) {
    if (const std::optional<SE3> T_world_map = frontend_.map_frame(lidar_sensor_)) registered->T_world_lidar = *T_world_map * estimate.T_world_lidar;
  }
  return registered;
}

}  // namespace hanzo::fusion::pipeline
