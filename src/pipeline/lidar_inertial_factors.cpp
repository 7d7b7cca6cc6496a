#include "lidar_inertial_factors.hpp"

#include <cmath>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"

namespace hanzo::fusion::pipeline {
namespace {

constexpr double kSweepHistorySeconds = 5.0;  // sweeps kept (keyframes reach the graph after the lag window)

using Matrix6d = Eigen::Matrix<double, 6, 6>;

// The covariance of a right perturbation of T moved to that of T M: T Exp(xi) M = T M Exp(Ad(M^-1) xi).
Matrix6d moved_right(const Matrix6d& covariance, const SE3& M) {
  const Matrix6d adjoint = M.inverse().adjoint();
  return adjoint * covariance * adjoint.transpose();
}

}  // namespace

LidarInertialFactors::LidarInertialFactors(const SE3& T_body_lidar, const graph::ImuPreintegrationConfig& imu, double accel_bias_random_walk,
                                           double gyro_bias_random_walk, LidarInertialFactorsConfig config)
    : T_body_lidar_(T_body_lidar), config_(config), chain_(imu, accel_bias_random_walk, gyro_bias_random_walk, config.priors) {}

void LidarInertialFactors::add_sweep(Timestamp time, const SE3& T_odometry_lidar, const Matrix6d& covariance, bool map_started) {
  if (!sweeps_.empty() && time <= sweeps_.back().time) return;
  if (map_started) ++map_;
  Matrix6d body = moved_right(covariance, T_body_lidar_.inverse());
  body.diagonal().head<3>().array() += config_.position_sigma_floor * config_.position_sigma_floor;
  body.diagonal().tail<3>().array() += config_.rotation_sigma_floor * config_.rotation_sigma_floor;
  sweeps_.push_back({time, T_odometry_lidar * T_body_lidar_.inverse(), 0.5 * (body + body.transpose()), map_});
  while ((time - sweeps_.front().time).seconds() > kSweepHistorySeconds) sweeps_.pop_front();
}

const LidarInertialFactors::Sweep* LidarInertialFactors::sweep_near(Timestamp time) const {
  const Sweep* nearest = nullptr;
  double best = config_.max_sweep_offset_s;
  for (const Sweep& sweep : sweeps_) {
    const double offset = std::abs((sweep.time - time).seconds());
    if (offset <= best) {
      best = offset;
      nearest = &sweep;
    }
  }
  return nearest;
}

void LidarInertialFactors::restart() {
  chain_.restart();
  previous_.reset();
}

LidarInertialFactors::KeyframeFactors LidarInertialFactors::keyframe(const msgs::Keyframe& keyframe, const graph::ImuBias& bias_body,
                                                                     const graph::Values& estimate) {
  KeyframeFactors out;
  const ImuKeyframeChain::Link link = chain_.link(keyframe, bias_body, estimate, out.update);
  out.imu_factor = link.imu_factor;
  chain_.close(keyframe, link.velocity, link, out.update);

  // The body's motion to the sweep, from the IMU's velocity where the IMU links the keyframe
  // (the graph's estimate carried forward), else the keyframe's.
  const Sweep* sweep = sweep_near(keyframe.timestamp);
  msgs::Keyframe moving = keyframe;
  moving.velocity = link.velocity;
  const std::optional<SE3> T_keyframe_sweep = sweep != nullptr ? chain_.body_motion(moving, link.bias, sweep->time) : std::nullopt;
  if (!T_keyframe_sweep) {
    logger()->debug("keyframe graph: keyframe {}: no registered sweep within {} s", keyframe.keyframe_id, config_.max_sweep_offset_s);
    return out;
  }
  const Anchor anchor{keyframe.keyframe_id, sweep->map, sweep->T_odometry_body * T_keyframe_sweep->inverse(),
                      moved_right(sweep->covariance, T_keyframe_sweep->inverse())};
  if (previous_ && previous_->map == anchor.map && keyframe.T_previous_current) {
    const SE3 T_previous_current = previous_->T_odometry_keyframe.inverse() * anchor.T_odometry_keyframe;
    const Matrix6d from_previous = moved_right(previous_->covariance, T_previous_current);
    Result<graph::GaussianNoise> noise = graph::GaussianNoise::from_covariance(from_previous + anchor.covariance);
    if (noise) {
      out.update.factors.emplace<graph::BetweenFactorSE3>(graph::X(previous_->keyframe), graph::X(keyframe.keyframe_id), T_previous_current,
                                                          *noise);
      out.lidar_factor = true;
    } else {
      logger()->debug("keyframe graph: keyframe {}: LiDAR relative motion: {}", keyframe.keyframe_id, noise.error().message);
    }
  }
  previous_ = anchor;
  return out;
}

}  // namespace hanzo::fusion::pipeline
