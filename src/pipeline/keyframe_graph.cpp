#include "hanzo/fusion/pipeline/keyframe_graph.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/graph/imu_factors.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/estimate/navigation_state.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"

namespace hanzo::fusion::pipeline {
namespace {

Result<graph::GaussianNoise> noise_of(const Eigen::MatrixXd& covariance, const std::string& what) {
  Result<graph::GaussianNoise> noise = graph::GaussianNoise::from_covariance(covariance);
  if (!noise) return Error(fmt::format("{}: {}", what, noise.error().message));
  return noise;
}

}  // namespace

KeyframeGraph::KeyframeGraph(KeyframeGraphConfig config) : config_(std::move(config)), smoother_(config_.smoother) {}

void KeyframeGraph::attach(Frontend& frontend) {
  frontend.set_keyframe_callback([this](const msgs::Keyframe& keyframe) { queued_keyframes_.push_back(keyframe); });
}

Status KeyframeGraph::add_keyframe(const msgs::Keyframe& keyframe, double relative_covariance_scale) {
  const uint64_t id = keyframe.keyframe_id;
  if (frontend_poses_.count(id) != 0) return Error(fmt::format("keyframe {}: already added", id));
  const SE3 T_world_body = keyframe.T_world_body.to_se3();
  if (keyframe.T_previous_current && keyframe.relative_covariance) {
    if (frontend_poses_.count(keyframe.previous_keyframe_id) == 0) {
      return Error(fmt::format("keyframe {}: its previous keyframe {} is unknown", id, keyframe.previous_keyframe_id));
    }
    graph::GaussianNoise noise;
    HANZO_ASSIGN_OR_RETURN(noise, noise_of(relative_covariance_scale * *keyframe.relative_covariance, fmt::format("keyframe {} relative covariance", id)));
    pending_.factors.emplace<graph::BetweenFactorSE3>(graph::X(keyframe.previous_keyframe_id), graph::X(id),
                                                      keyframe.T_previous_current->to_se3(), noise);
  } else {
    if (!keyframe.pose_covariance) return Error(fmt::format("keyframe {}: the first keyframe needs a pose covariance", id));
    // (position world, orientation body) -> tangent (rho = R^T dp, phi).
    Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Identity();
    J.topLeftCorner<3, 3>() = T_world_body.rotation().matrix().transpose();
    Eigen::Matrix<double, 6, 6> covariance = *keyframe.pose_covariance;
    if (config_.first_position_sigma > 0.0) {
      covariance.topRows<3>().setZero();
      covariance.leftCols<3>().setZero();
      covariance.topLeftCorner<3, 3>() = Eigen::Matrix3d::Identity() * config_.first_position_sigma * config_.first_position_sigma;
    }
    graph::GaussianNoise noise;
    HANZO_ASSIGN_OR_RETURN(noise, noise_of(J * covariance * J.transpose(), fmt::format("keyframe {} pose covariance", id)));
    pending_.factors.emplace<graph::PriorFactorSE3>(graph::X(id), T_world_body, noise);
    mark_pose_graph_factor();
  }
  if (config_.level_from_keyframes && keyframe.pose_covariance) {
    // r = R^T (-g) - up_body moves by [up_body]x dtheta (body frame); nothing along gravity.
    const Eigen::Vector3d up_body = T_world_body.rotation().inverse() * Eigen::Vector3d(0.0, 0.0, estimate::kStandardGravity);
    const Eigen::Matrix3d attitude = keyframe.pose_covariance->bottomRightCorner<3, 3>() +
                                     Eigen::Matrix3d::Identity() * config_.level_sigma_floor * config_.level_sigma_floor;
    const Eigen::Matrix3d hat = SO3::hat(up_body);
    const Eigen::Matrix3d covariance = config_.level_correlated_keyframes * (hat * attitude * hat.transpose()) +
                                       Eigen::Matrix3d::Identity() * std::pow(estimate::kStandardGravity * config_.level_sigma_floor, 2);
    graph::GaussianNoise level_noise;
    HANZO_ASSIGN_OR_RETURN(level_noise, noise_of(covariance, fmt::format("keyframe {} attitude covariance", id)));
    pending_.factors.emplace<graph::GravityFactor>(graph::X(id), up_body, level_noise);
    mark_pose_graph_factor();
  }
  if (config_.window_keyframes > 0) {
    window_.push_back({id, keyframe.T_previous_current ? std::optional<uint64_t>(keyframe.previous_keyframe_id) : std::nullopt,
                       keyframe.relative_covariance.value_or(Eigen::Matrix<double, 6, 6>::Identity())});
  }
  pending_.values.insert(graph::X(id), initial_pose(keyframe));
  frontend_poses_[id] = T_world_body;
  keyframe_at_[keyframe.timestamp.nanoseconds()] = id;
  keyframe_times_[id] = keyframe.timestamp;
  latest_keyframe_ = id;
  return ok_status();
}

SE3 KeyframeGraph::initial_pose(const msgs::Keyframe& keyframe) const {
  if (!keyframe.T_previous_current) return keyframe.T_world_body.to_se3();
  const graph::Key previous = graph::X(keyframe.previous_keyframe_id);
  Result<SE3> T_world_previous = pending_.values.exists(previous) ? pending_.values.at<SE3>(previous) : smoother_.estimate().at<SE3>(previous);
  if (!T_world_previous) return keyframe.T_world_body.to_se3();
  return *T_world_previous * keyframe.T_previous_current->to_se3();
}

void KeyframeGraph::add_factors(const graph::GraphUpdate& update) {
  for (const graph::FactorPointer& factor : update.factors.factors()) pending_.factors.add(factor);
  for (const auto& [key, value] : update.values.all()) {
    if (!smoother_.estimate().exists(key)) pending_.values.insert(key, value);  // known: its estimate stays
  }
}

Status KeyframeGraph::add_gps(Timestamp time, const Eigen::Vector3d& position_world, const Eigen::Matrix3d& covariance,
                              const Eigen::Vector3d& lever_arm) {
  if (!position_world.allFinite() || !lever_arm.allFinite()) return Error("gps: non-finite position or lever arm");
  if (Result<graph::GaussianNoise> noise = noise_of(covariance, "gps covariance"); !noise) return noise.error();
  pending_fixes_.push_back({time, position_world, lever_arm, covariance});
  return ok_status();
}

Status KeyframeGraph::add_gps_at_keyframe(uint64_t keyframe_id, const Eigen::Vector3d& position_world, const Eigen::Matrix3d& covariance,
                                          const Eigen::Vector3d& lever_arm, double seconds_from_keyframe) {
  if (frontend_poses_.count(keyframe_id) == 0) return Error(fmt::format("gps: keyframe {} is unknown", keyframe_id));
  if (!position_world.allFinite() || !lever_arm.allFinite() || !std::isfinite(seconds_from_keyframe)) {
    return Error("gps: non-finite position, lever arm or time");
  }
  return add_fix_factor(keyframe_id, position_world, covariance, lever_arm, seconds_from_keyframe, true);
}

Status KeyframeGraph::add_fix_factor(uint64_t keyframe_id, const Eigen::Vector3d& position_world, const Eigen::Matrix3d& covariance,
                                     const Eigen::Vector3d& lever_arm, double seconds_from_keyframe, bool robust) {
  const graph::RobustKernel kernel{robust ? graph::RobustKernel::Type::kCauchy : graph::RobustKernel::Type::kNone, config_.gps_cauchy_scale};
  const double tau = config_.gnss_error_correlation_s;
  if (!(tau > 0.0)) {
    graph::GaussianNoise noise;
    HANZO_ASSIGN_OR_RETURN(noise, noise_of(covariance, "gps covariance"));
    pending_.factors.emplace_robust<graph::GpsFactor>(kernel, graph::X(keyframe_id), position_world, lever_arm, noise);
    mark_pose_graph_factor();
    return ok_status();
  }
  // The error in units of the fix's correlated standard deviations (S S^T = (1 - white) Sigma),
  // a unit-variance process: a receiver's error grows and shrinks with the accuracy it reports
  // (a canyon's metres, open sky's centimetres) while staying correlated in those units.
  const double white = std::clamp(config_.gnss_white_fraction, 1e-3, 1.0);
  const Eigen::LLT<Eigen::Matrix3d> correlated((1.0 - white) * covariance);
  if (correlated.info() != Eigen::Success) return Error("gps covariance: not positive definite");
  // The fix's own noise, and what the process moves between the keyframe and the fix.
  const double decay = std::exp(-std::abs(seconds_from_keyframe) / tau);
  graph::GaussianNoise noise;
  HANZO_ASSIGN_OR_RETURN(noise, noise_of((white + (1.0 - white) * (1.0 - decay * decay)) * covariance, "gps covariance"));
  const graph::Key error = graph::E(keyframe_id);
  if (!pending_.values.exists(error) && !smoother_.estimate().exists(error)) {
    const Timestamp time = keyframe_times_.at(keyframe_id);
    if (latest_gnss_error_ && latest_gnss_error_->second <= time) {
      const graph::Key previous = graph::E(latest_gnss_error_->first);
      const double dt = (time - latest_gnss_error_->second).seconds();
      std::shared_ptr<graph::GaussMarkovFactor> process;
      HANZO_ASSIGN_OR_RETURN(process, graph::GaussMarkovFactor::create(previous, error, dt, tau, Eigen::Matrix3d::Identity()));
      pending_.factors.add(process);
      mark_pose_graph_factor();
      Result<Eigen::Vector3d> previous_value =
          pending_.values.exists(previous) ? pending_.values.at<Eigen::Vector3d>(previous) : smoother_.estimate().at<Eigen::Vector3d>(previous);
      pending_.values.insert(error, Eigen::Vector3d(process->decay() * (previous_value ? *previous_value : Eigen::Vector3d::Zero())));
    } else {
      pending_.factors.emplace<graph::PriorFactorVector3>(error, Eigen::Vector3d::Zero(), graph::GaussianNoise::from_sigmas(Eigen::Vector3d::Ones()).value());
      mark_pose_graph_factor();
      pending_.values.insert(error, Eigen::Vector3d::Zero());
    }
    if (!latest_gnss_error_ || latest_gnss_error_->second <= time) latest_gnss_error_ = {keyframe_id, time};
  }
  pending_.factors.emplace_robust<graph::GpsFactor>(kernel, graph::X(keyframe_id), error, Eigen::Matrix3d(correlated.matrixL()), position_world, lever_arm,
                                                    noise);
  mark_pose_graph_factor();
  return ok_status();
}

Status KeyframeGraph::add_loop_closure(uint64_t from, uint64_t to, const SE3& T_from_to, const Eigen::Matrix<double, 6, 6>& covariance) {
  for (uint64_t id : {from, to}) {
    if (frontend_poses_.count(id) == 0) return Error(fmt::format("loop closure {} - {}: keyframe {} is unknown", from, to, id));
  }
  if (from == to) return Error(fmt::format("loop closure {} - {}: a keyframe with itself", from, to));
  graph::GaussianNoise noise;
  HANZO_ASSIGN_OR_RETURN(noise, noise_of(covariance, fmt::format("loop closure {} - {} covariance", from, to)));
  pending_.factors.emplace_robust<graph::BetweenFactorSE3>(graph::RobustKernel{graph::RobustKernel::Type::kDcs, config_.loop_closure_dcs_phi},
                                                           graph::X(from), graph::X(to), T_from_to, noise);
  mark_pose_graph_factor();
  loop_closure_pending_ = true;
  return ok_status();
}

Result<KeyframeGraphUpdate> KeyframeGraph::process(Frontend* frontend) {
  KeyframeGraphUpdate update;
  while (!queued_keyframes_.empty()) {
    const msgs::Keyframe keyframe = queued_keyframes_.front();
    queued_keyframes_.pop_front();
    HANZO_RETURN_IF_ERROR(add_keyframe(keyframe));
    ++update.keyframes_added;
  }
  // GNSS fixes onto the keyframe nearest in time, once one is close enough.
  const auto max_offset = static_cast<int64_t>(config_.gps_max_time_offset_s * 1e9);
  const int64_t latest_time = keyframe_at_.empty() ? INT64_MIN : keyframe_at_.rbegin()->first;
  for (auto fix = pending_fixes_.begin(); fix != pending_fixes_.end();) {
    const int64_t time = fix->time.nanoseconds();
    std::optional<uint64_t> nearest;
    int64_t best = max_offset + 1;
    for (auto it = keyframe_at_.lower_bound(time - max_offset); it != keyframe_at_.end() && it->first <= time + max_offset; ++it) {
      if (std::llabs(it->first - time) < best) {
        best = std::llabs(it->first - time);
        nearest = it->second;
      }
    }
    if (nearest) {
      HANZO_RETURN_IF_ERROR(add_fix_factor(*nearest, fix->position_world, fix->covariance, fix->lever_arm,
                                           (fix->time - keyframe_times_.at(*nearest)).seconds(), false));
      fix = pending_fixes_.erase(fix);
    } else if (time + max_offset < latest_time) {
      ++update.fixes_dropped;
      fix = pending_fixes_.erase(fix);
    } else {
      ++fix;
    }
  }
  update.factors_added = static_cast<int>(pending_.factors.size());
  if (pending_.factors.size() == 0 && pending_.values.size() == 0) return update;
  if (Result<graph::IncrementalUpdateSummary> updated = smoother_.update(pending_.factors, pending_.values); !updated) {
    return Error(fmt::format("keyframe graph: {}", updated.error().message));
  }
  pending_ = graph::GraphUpdate{};
  while (config_.window_keyframes > 0 && window_.size() > static_cast<std::size_t>(config_.window_keyframes)) {
    HANZO_RETURN_IF_ERROR(leave_window(update));
  }
  if (config_.batch_on_loop_closure && loop_closure_pending_) {
    // Loop closures soon after the last batch wait (their factors are in) for the next one.
    const Timestamp now = latest_keyframe_ ? keyframe_times_.at(*latest_keyframe_) : Timestamp();
    if (last_loop_batch_ && (now - *last_loop_batch_).seconds() < config_.loop_batch_interval_s) return update;
    if (Result<graph::OptimizationSummary> batch = smoother_.wait_for_batch(); !batch) {
      return Error(fmt::format("keyframe graph: {}", batch.error().message));
    }
    last_loop_batch_ = now;
    update.loop_batch = true;
  }
  if (config_.batch_interval_s > 0.0 && latest_keyframe_) {
    const Timestamp now = keyframe_times_.at(*latest_keyframe_);
    if (!last_periodic_batch_ || (now - *last_periodic_batch_).seconds() >= config_.batch_interval_s) {
      if (Result<graph::OptimizationSummary> batch = smoother_.wait_for_batch(); !batch) {
        return Error(fmt::format("keyframe graph: {}", batch.error().message));
      }
      last_periodic_batch_ = now;
    }
  }
  const bool loop_closed = loop_closure_pending_;
  loop_closure_pending_ = false;
  if (frontend != nullptr && latest_keyframe_ && (loop_closed || !config_.correct_on_loop_closures_only)) {
    const SE3 optimized = smoother_.estimate().at<SE3>(graph::X(*latest_keyframe_)).value();
    update.correction_translation_m = (optimized.translation() - frontend_poses_.at(*latest_keyframe_).translation()).norm();
    HANZO_RETURN_IF_ERROR(frontend->apply_correction(*latest_keyframe_, optimized));
    update.corrected_session = true;
  }
  return update;
}

Status KeyframeGraph::leave_window(KeyframeGraphUpdate& update) {
  const WindowKeyframe leaving = window_.front();
  window_.pop_front();
  const WindowKeyframe& next = window_.front();
  const graph::Values& estimate = smoother_.estimate();
  // Its velocity, biases and the landmarks it saw go, with its pose's window factors.
  std::set<graph::Key> keys = {graph::X(leaving.id)};
  for (const graph::Key key : {graph::V(leaving.id), graph::B(leaving.id)}) {
    if (estimate.exists(key)) keys.insert(key);
  }
  std::vector<uint64_t> landmarks;
  for (const graph::FactorPointer& factor : smoother_.factors_of(graph::X(leaving.id))) {
    if (pose_graph_factors_.count(factor.get())) continue;
    for (const graph::Key key : factor->keys()) {
      if (graph::symbol_character(key) == 'l' && keys.insert(key).second) landmarks.push_back(graph::symbol_index(key));
    }
  }
  // The pose graph's link to the next keyframe, from the window's estimate before it changes.
  std::optional<graph::FactorGraph> link;
  if (next.previous == leaving.id) {
    const Result<SE3> T_world_leaving = estimate.at<SE3>(graph::X(leaving.id));
    const Result<SE3> T_world_next = estimate.at<SE3>(graph::X(next.id));
    graph::GaussianNoise noise;
    HANZO_ASSIGN_OR_RETURN(noise, noise_of(next.relative_covariance, fmt::format("keyframe {} relative covariance", next.id)));
    if (T_world_leaving && T_world_next) {
      link.emplace();
      link->emplace<graph::BetweenFactorSE3>(graph::X(leaving.id), graph::X(next.id), T_world_leaving->inverse() * *T_world_next, noise);
    }
  }
  Result<std::vector<graph::Key>> marginalized =
      smoother_.marginalize(keys, [this](const graph::Factor& factor) { return pose_graph_factors_.count(&factor) != 0; });
  if (!marginalized) return Error(fmt::format("keyframe graph: keyframe {} leaving the window: {}", leaving.id, marginalized.error().message));
  if (link) {
    pose_graph_factors_.insert(link->factors().back().get());
    if (Result<graph::IncrementalUpdateSummary> linked = smoother_.update(*link, {}); !linked) {
      return Error(fmt::format("keyframe graph: the pose graph's link to keyframe {}: {}", next.id, linked.error().message));
    }
  }
  ++update.keyframes_left_window;
  update.marginalized_landmarks.insert(update.marginalized_landmarks.end(), landmarks.begin(), landmarks.end());
  return ok_status();
}

bool KeyframeGraph::has_pending_work() const {
  return !queued_keyframes_.empty() || !pending_fixes_.empty() || pending_.factors.size() > 0 || pending_.values.size() > 0;
}

std::optional<uint64_t> KeyframeGraph::window_start() const {
  if (!window_.empty()) return window_.front().id;
  return std::nullopt;
}

std::optional<SE3> KeyframeGraph::optimized_pose(uint64_t keyframe_id) const {
  const Result<SE3> pose = smoother_.estimate().at<SE3>(graph::X(keyframe_id));
  return pose ? std::optional<SE3>(*pose) : std::nullopt;
}

std::optional<SE3> KeyframeGraph::frontend_pose(uint64_t keyframe_id) const {
  const auto found = frontend_poses_.find(keyframe_id);
  return found != frontend_poses_.end() ? std::optional<SE3>(found->second) : std::nullopt;
}

}  // namespace hanzo::fusion::pipeline

namespace hanzo::fusion::pipeline {

std::optional<Timestamp> KeyframeGraph::keyframe_time(uint64_t keyframe_id) const {
  const auto found = keyframe_times_.find(keyframe_id);
  return found != keyframe_times_.end() ? std::optional<Timestamp>(found->second) : std::nullopt;
}

std::vector<uint64_t> KeyframeGraph::keyframe_ids() const {
  std::vector<uint64_t> ids;
  for (const auto& [id, pose] : frontend_poses_) ids.push_back(id);
  return ids;
}

}  // namespace hanzo::fusion::pipeline
