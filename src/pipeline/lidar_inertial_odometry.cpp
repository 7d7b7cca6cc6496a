#include "hanzo/fusion/pipeline/lidar_inertial_odometry.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::pipeline {

LidarInertialOdometry::LidarInertialOdometry(Session& session, std::string lidar_sensor, const SE3& T_body_lidar,
                                             LidarInertialOdometryConfig config)
    : session_(session), lidar_sensor_(std::move(lidar_sensor)), T_body_lidar_(T_body_lidar), config_(std::move(config)) {}

Result<lidar::LidarOdometryEstimate> LidarInertialOdometry::process(const msgs::PointCloudMessage& scan) {
  auto refuse = [this](const std::string& reason) -> Error {
    ++statistics_.refused;
    return Error(fmt::format("lidar-inertial odometry ({}): {}", lidar_sensor_, reason));
  };
  auto cloud = cloud::from_message(scan);
  if (!cloud) return refuse(cloud.error().message);
  const double middle = cloud->has_times() ? 0.5 * static_cast<double>(*std::max_element(cloud->times.begin(), cloud->times.end())) : 0.0;
  const Timestamp middle_time = scan.timestamp + Duration::from_seconds(middle);
  const std::optional<SE3> T_world_body = session_.pose_at(middle_time);
  if (!T_world_body) {
    return refuse(fmt::format("no filter pose at {:.6f} s (the session is not initialized, or the IMU has not reached the "
                              "sweep yet, or the sweep is older than the lag window)", middle_time.seconds()));
  }
  const SE3 T_world_lidar = *T_world_body * T_body_lidar_;
  // Backend corrections since the previous sweep moved the session's world: follow them.
  const SE3 correction = session_.world_correction();
  if (!odometry_) correction_at_last_scan_ = correction;  // the odometry starts in today's world
  const SE3 correction_since = correction * correction_at_last_scan_.inverse();
  if (last_filter_pose_) last_filter_pose_ = correction_since * *last_filter_pose_;
  T_world_odometry_ = correction_since * T_world_odometry_;
  correction_at_last_scan_ = correction;
  if (!odometry_) odometry_ = std::make_unique<lidar::LidarOdometry>(config_.odometry, T_world_lidar);
  // The filter's motion since the previous sweep (not its absolute pose: where the filter and
  // the odometry disagree, e.g. after a gated update, the motion is still right).
  std::optional<SE3> motion;
  if (last_filter_pose_) motion = last_filter_pose_->inverse() * T_world_lidar;
  auto estimate = odometry_->add_scan(scan.timestamp, *cloud, motion);
  if (!estimate) return refuse(estimate.error().message);
  last_filter_pose_ = T_world_lidar;
  ++statistics_.scans;
  statistics_.degenerate += estimate->degenerate ? 1 : 0;
  statistics_.weather_degraded += estimate->weather_degraded ? 1 : 0;

  // Covariance over (position in the world, rotation in the sensor frame): the tangent's
  // translation rho is in the sensor frame (right perturbation), so position = R rho.
  Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Identity();
  J.topLeftCorner<3, 3>() = (T_world_odometry_ * estimate->T_world_lidar).rotation().matrix();
  Eigen::Matrix<double, 6, 6> covariance = J * estimate->covariance * J.transpose();
  covariance = 0.5 * (covariance + covariance.transpose());
  covariance.diagonal().head<3>().array() += config_.position_sigma_floor * config_.position_sigma_floor;
  covariance.diagonal().tail<3>().array() += config_.rotation_sigma_floor * config_.rotation_sigma_floor;
  if (estimate->weather_degraded) covariance *= config_.weather_covariance_scale;
  if (Status fused = session_.push_pose(lidar_sensor_, estimate->time, T_world_odometry_ * estimate->T_world_lidar, covariance); fused) {
    ++statistics_.fused;
  } else {
    return Error(fmt::format("lidar-inertial odometry ({}): registered, but the session refused the pose: {}", lidar_sensor_,
                             fused.error().message));
  }
  return estimate;
}

}  // namespace hanzo::fusion::pipeline
