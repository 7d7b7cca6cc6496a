#include "imu_keyframe_chain.hpp"

#include <cmath>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/graph/imu_factors.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"

namespace hanzo::fusion::pipeline {
namespace {

constexpr double kMaxImuGapSeconds = 0.1;    // longer between two samples: the IMU was lost
constexpr double kImuHistorySeconds = 30.0;  // samples kept when no keyframe comes

}  // namespace

std::optional<estimate::ImuSample> BodyImu::convert(const msgs::ImuMessage& imu) {
  if (!imu.angular_velocity.allFinite() || !imu.linear_acceleration.allFinite()) return std::nullopt;
  const Timestamp time = imu.timestamp + time_offset_;
  const Eigen::Vector3d rate = T_body_imu_.rotation() * imu.angular_velocity;
  const Eigen::Vector3d& lever_arm = T_body_imu_.translation();
  Eigen::Vector3d angular_acceleration = Eigen::Vector3d::Zero();
  if (previous_rate_ && time > previous_rate_->first) {
    angular_acceleration = (rate - previous_rate_->second) / (time - previous_rate_->first).seconds();
  }
  previous_rate_.emplace(time, rate);
  const Eigen::Vector3d specific_force = T_body_imu_.rotation() * imu.linear_acceleration - angular_acceleration.cross(lever_arm) -
                                         rate.cross(rate.cross(lever_arm));
  return estimate::ImuSample{time, rate, specific_force};
}

ImuChainNoise imu_chain_noise(const config::FusionConfig& config, const config::SensorConfig& imu) {
  const config::CovarianceConfig& covariance = config.frontend.covariance;
  ImuChainNoise noise;
  noise.preintegration.process_noise_accel = covariance.process_noise_accel;
  noise.preintegration.process_noise_gyro = covariance.process_noise_gyro;
  noise.preintegration.sample_interval = 1.0 / imu.rate_hz;
  noise.accel_bias_random_walk = covariance.accel_bias_random_walk;
  noise.gyro_bias_random_walk = covariance.gyro_bias_random_walk;
  return noise;
}

ImuKeyframeChain::ImuKeyframeChain(const graph::ImuPreintegrationConfig& imu, double accel_bias_random_walk, double gyro_bias_random_walk,
                                   ImuChainPriors priors)
    : imu_(imu), accel_bias_random_walk_(accel_bias_random_walk), gyro_bias_random_walk_(gyro_bias_random_walk), priors_(priors) {}

void ImuKeyframeChain::add_imu(const estimate::ImuSample& sample) {
  if (!samples_.empty() && sample.timestamp <= samples_.back().timestamp) return;
  samples_.push_back(sample);
  const Timestamp keep_from = previous_ ? previous_->time : sample.timestamp - Duration::from_seconds(kImuHistorySeconds);
  while (samples_.size() > 1 && samples_[1].timestamp <= keep_from) samples_.pop_front();
  while (samples_.size() > 1 && (sample.timestamp - samples_.front().timestamp).seconds() > kImuHistorySeconds) samples_.pop_front();
}

std::optional<graph::ImuPreintegration> ImuKeyframeChain::preintegrate(Timestamp from, Timestamp to, const graph::ImuBias& bias) const {
  // Each sample's reading holds from the sample before it (as the filters propagate).
  graph::ImuPreintegration preintegration(imu_, bias);
  for (size_t k = 1; k < samples_.size(); ++k) {
    const Timestamp start = samples_[k - 1].timestamp;
    const Timestamp end = samples_[k].timestamp;
    if (end <= from) continue;
    if (start >= to) break;
    if ((end - start).seconds() > kMaxImuGapSeconds) return std::nullopt;
    const double dt = (std::min(end, to) - std::max(start, from)).seconds();
    if (dt <= 0.0) continue;
    if (!preintegration.integrate(samples_[k].linear_acceleration, samples_[k].angular_velocity, dt)) return std::nullopt;
  }
  // The interval must be covered: samples up to `to` and from `from` on.
  if (preintegration.sample_count() == 0 || std::abs(preintegration.delta_time() - (to - from).seconds()) > 1e-6) return std::nullopt;
  return preintegration;
}

std::optional<SE3> ImuKeyframeChain::body_motion(const msgs::Keyframe& keyframe, const graph::ImuBias& bias, Timestamp time) const {
  if (time == keyframe.timestamp) return SE3();
  const SE3 T_world_keyframe = keyframe.T_world_body.to_se3();
  if (time > keyframe.timestamp) {
    const std::optional<graph::ImuPreintegration> interval = preintegrate(keyframe.timestamp, time, bias);
    if (!interval) return std::nullopt;
    SE3 T_world_at;
    Eigen::Vector3d velocity_at;
    interval->predict(T_world_keyframe, keyframe.velocity, bias, &T_world_at, &velocity_at);
    return T_world_keyframe.inverse() * T_world_at;
  }
  const std::optional<graph::ImuPreintegration> interval = preintegrate(time, keyframe.timestamp, bias);
  if (!interval) return std::nullopt;
  // Eq. 38 solved for the state at `time` (f) from the keyframe's (k):
  //   R_f = R_k dR^T,  v_f = v_k - g T - R_f dv,  p_f = p_k - v_f T - 1/2 g T^2 - R_f dp.
  const double T = interval->delta_time();
  const graph::ImuDeltas& delta = interval->deltas();
  const SO3 R_world_at = T_world_keyframe.rotation() * delta.rotation.inverse();
  const Eigen::Vector3d velocity_at = keyframe.velocity - imu_.gravity * T - R_world_at * delta.velocity;
  const Eigen::Vector3d position_at = T_world_keyframe.translation() - velocity_at * T - 0.5 * imu_.gravity * T * T - R_world_at * delta.position;
  return T_world_keyframe.inverse() * SE3(R_world_at, position_at);
}

ImuKeyframeChain::Link ImuKeyframeChain::link(const msgs::Keyframe& keyframe, const graph::ImuBias& bias_body, const graph::Values& estimate,
                                              graph::GraphUpdate& out) const {
  Link link;
  link.velocity = keyframe.velocity;
  link.bias = bias_body;
  if (!previous_ || !keyframe.T_previous_current || keyframe.previous_keyframe_id != previous_->id) return link;
  const uint64_t id = keyframe.keyframe_id;
  // The preintegration from the graph's bias at the previous keyframe, B(k) started there too
  // (the filter's bias would be far off the random walk's sigmas).
  const Result<SE3> T_world_previous = estimate.at<SE3>(graph::X(previous_->id));
  const Result<Eigen::Vector3d> velocity_previous = estimate.at<Eigen::Vector3d>(graph::V(previous_->id));
  const Result<graph::ImuBias> bias_previous = estimate.at<graph::ImuBias>(graph::B(previous_->id));
  if (!T_world_previous || !velocity_previous || !bias_previous) return link;
  const std::optional<graph::ImuPreintegration> preintegration = preintegrate(previous_->time, keyframe.timestamp, *bias_previous);
  if (!preintegration) {
    logger()->debug("keyframe graph: keyframe {}: the IMU does not cover the interval since keyframe {}", id, previous_->id);
    return link;
  }
  Result<std::shared_ptr<graph::ImuFactor>> imu =
      graph::ImuFactor::create(graph::X(previous_->id), graph::V(previous_->id), graph::X(id), graph::V(id), graph::B(previous_->id), *preintegration);
  Result<std::shared_ptr<graph::ImuBiasRandomWalkFactor>> walk = graph::ImuBiasRandomWalkFactor::create(
      graph::B(previous_->id), graph::B(id), preintegration->delta_time(), accel_bias_random_walk_, gyro_bias_random_walk_);
  if (!imu || !walk) {
    logger()->debug("keyframe graph: keyframe {}: {}", id, imu ? walk.error().message : imu.error().message);
    return link;
  }
  out.factors.add(*imu);
  out.factors.add(*walk);
  link.imu_factor = true;
  SE3 T_world_predicted;
  preintegration->predict(*T_world_previous, *velocity_previous, *bias_previous, &T_world_predicted, &link.velocity);
  link.bias = *bias_previous;
  return link;
}

void ImuKeyframeChain::close(const msgs::Keyframe& keyframe, const Eigen::Vector3d& velocity, const Link& link, graph::GraphUpdate& out) {
  const uint64_t id = keyframe.keyframe_id;
  if (!link.imu_factor) {
    Eigen::Matrix<double, 6, 1> bias_sigmas;
    bias_sigmas << Eigen::Vector3d::Constant(priors_.accel_bias_sigma), Eigen::Vector3d::Constant(priors_.gyro_bias_sigma);
    out.factors.emplace<graph::PriorFactorVector3>(graph::V(id), velocity,
                                                   graph::GaussianNoise::from_sigmas(Eigen::Vector3d::Constant(priors_.velocity_sigma)).value());
    out.factors.emplace<graph::PriorFactorImuBias>(graph::B(id), link.bias, graph::GaussianNoise::from_sigmas(bias_sigmas).value());
  }
  out.values.insert(graph::V(id), velocity);
  out.values.insert(graph::B(id), link.bias);
  previous_ = Anchor{id, keyframe.timestamp};
}

}  // namespace hanzo::fusion::pipeline
