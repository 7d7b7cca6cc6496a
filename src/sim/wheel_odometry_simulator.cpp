#include "hanzo/fusion/sim/wheel_odometry_simulator.hpp"

#include <algorithm>
#include <cmath>

namespace hanzo::fusion::sim {

WheelOdometrySimulator::WheelOdometrySimulator(WheelOdometrySimulatorConfig config, const SplineTrajectory& trajectory)
    : config_(std::move(config)), trajectory_(&trajectory), random_(config_.seed) {}

const WheelSlipEpisode* WheelOdometrySimulator::slip_at(Timestamp time) const {
  for (const WheelSlipEpisode& slip : config_.slips) {
    if (time >= slip.start && time <= slip.end) return &slip;
  }
  return nullptr;
}

Eigen::Vector2d WheelOdometrySimulator::axle_speed_and_yaw_rate(Timestamp time) const {
  const TrajectorySample body = trajectory_->sample(time);
  const Eigen::Vector3d& lever = config_.T_body_wheels.translation();
  const Eigen::Vector3d velocity_body =
      body.T_world_body.rotation().inverse() * body.velocity_world + body.angular_velocity_body.cross(lever);
  const SO3 R_wheels_body = config_.T_body_wheels.rotation().inverse();
  return {(R_wheels_body * velocity_body).x(), (R_wheels_body * body.angular_velocity_body).z()};
}

msgs::WheelOdometryMessage WheelOdometrySimulator::measure(Timestamp time) {
  if (previous_time_ && time > *previous_time_) {
    const double interval = (time - *previous_time_).seconds();
    const int steps = std::max(1, static_cast<int>(std::ceil(interval / 1e-3)));
    const double dt = interval / steps;
    double left = 0.0, right = 0.0;
    for (int step = 0; step < steps; ++step) {
      const Eigen::Vector2d motion = axle_speed_and_yaw_rate(*previous_time_ + Duration::from_seconds((step + 0.5) * dt));
      left += (motion.x() - motion.y() * config_.wheel_separation / 2.0) * dt;
      right += (motion.x() + motion.y() * config_.wheel_separation / 2.0) * dt;
    }
    std::normal_distribution<double> normal(0.0, 1.0);
    left *= config_.scale_error.x() * (1.0 + config_.distance_noise * normal(random_));
    right *= config_.scale_error.y() * (1.0 + config_.distance_noise * normal(random_));
    if (const WheelSlipEpisode* slip = slip_at(time)) {
      left *= slip->left_scale;
      right *= slip->right_scale;
    }
    left_ += left;
    right_ += right;
  }
  previous_time_ = time;
  msgs::WheelOdometryMessage message;
  message.timestamp = time;
  message.frame_id = config_.frame_id;
  message.left_distance = left_;
  message.right_distance = right_;
  message.wheel_separation = config_.wheel_separation;
  message.wheel_radius = config_.wheel_radius;
  return message;
}

}  // namespace hanzo::fusion::sim
