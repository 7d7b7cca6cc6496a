#include "moving_start.hpp"

#include <algorithm>

#include <Eigen/Geometry>

#include "hanzo/fusion/estimate/attitude_models.hpp"
#include "hanzo/fusion/estimate/static_alignment.hpp"

namespace hanzo::fusion::pipeline {

SO3 tilt_from_moving_imu(const std::vector<estimate::ImuSample>& samples) {
  SO3 R_last_sample;  // sample i's frame in the last sample's, walking backwards
  Eigen::Vector3d force_sum = samples.back().linear_acceleration;
  for (std::size_t i = samples.size() - 1; i > 0; --i) {
    const double dt = (samples[i].timestamp - samples[i - 1].timestamp).seconds();
    R_last_sample = R_last_sample * SO3::exp(-0.5 * (samples[i].angular_velocity + samples[i - 1].angular_velocity) * dt);
    force_sum += R_last_sample * samples[i - 1].linear_acceleration;
  }
  const Eigen::Quaterniond tilt = Eigen::Quaterniond::FromTwoVectors(force_sum.normalized(), Eigen::Vector3d::UnitZ());
  const Eigen::Vector3d roll_pitch_yaw = estimate::roll_pitch_yaw(tilt.toRotationMatrix());
  return estimate::rotation_from_roll_pitch_yaw(roll_pitch_yaw.x(), roll_pitch_yaw.y(), 0.0);
}

SO3 gyro_rotation(const std::vector<estimate::ImuSample>& samples, Timestamp from, Timestamp to) {
  SO3 R_from_to;
  for (std::size_t i = 1; i < samples.size(); ++i) {
    const Timestamp start = std::max(samples[i - 1].timestamp, from), end = std::min(samples[i].timestamp, to);
    if (end <= start) continue;
    R_from_to = R_from_to * SO3::exp(0.5 * (samples[i - 1].angular_velocity + samples[i].angular_velocity) * (end - start).seconds());
  }
  return R_from_to;
}

std::map<uint64_t, Eigen::Vector3d> triangulate_stereo(const std::vector<vision::FeatureObservation>& observations,
                                                       const std::vector<vision::MsckfCamera>& cameras, double max_depth_m) {
  std::map<uint64_t, Eigen::Vector3d> points;
  if (cameras.size() != 2) return points;
  std::map<uint64_t, Eigen::Vector2d> left;
  for (const vision::FeatureObservation& observation : observations) {
    if (observation.camera == 0) left[observation.feature_id] = observation.normalized;
  }
  const SE3 T_left_right = cameras[0].T_body_camera.inverse() * cameras[1].T_body_camera;
  for (const vision::FeatureObservation& observation : observations) {
    const auto found = left.find(observation.feature_id);
    if (observation.camera != 1 || found == left.end()) continue;
    // depth_left r_left = t + depth_right R r_right, least squares in the two depths.
    const Eigen::Vector3d ray_left = found->second.homogeneous();
    const Eigen::Vector3d ray_right = T_left_right.rotation() * observation.normalized.homogeneous();
    Eigen::Matrix<double, 3, 2> A;
    A << ray_left, -ray_right;
    const Eigen::Vector2d depths = (A.transpose() * A).ldlt().solve(A.transpose() * T_left_right.translation());
    if (!depths.allFinite() || depths.x() <= 0.1 || depths.y() <= 0.1 || depths.x() > max_depth_m) continue;
    points[observation.feature_id] = cameras[0].T_body_camera * Eigen::Vector3d(depths.x() * ray_left);
  }
  return points;
}

std::optional<Eigen::Vector3d> stereo_velocity(const std::map<uint64_t, Eigen::Vector3d>& previous_points,
                                               const std::map<uint64_t, Eigen::Vector3d>& current_points, const SO3& R_previous_current,
                                               double dt, int min_points) {
  if (!(dt > 0.0)) return std::nullopt;
  std::vector<double> axes[3];
  for (const auto& [id, current] : current_points) {
    const auto previous = previous_points.find(id);
    if (previous == previous_points.end()) continue;
    const Eigen::Vector3d moved = previous->second - R_previous_current * current;  // the body's move, previous frame
    for (int axis = 0; axis < 3; ++axis) axes[axis].push_back(moved[axis]);
  }
  if (static_cast<int>(axes[0].size()) < min_points) return std::nullopt;
  Eigen::Vector3d median;
  for (int axis = 0; axis < 3; ++axis) {
    std::nth_element(axes[axis].begin(), axes[axis].begin() + static_cast<std::ptrdiff_t>(axes[axis].size() / 2), axes[axis].end());
    median[axis] = axes[axis][axes[axis].size() / 2];
  }
  return R_previous_current.inverse() * median / dt;
}

}  // namespace hanzo::fusion::pipeline
