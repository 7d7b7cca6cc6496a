#include "hanzo/fusion/pipeline/wheel_slip_monitor.hpp"

#include <cmath>

namespace hanzo::fusion::pipeline {
namespace {

constexpr double kHistorySeconds = 5.0;  // kept beyond the window: sweeps are registered late

}  // namespace

void WheelSlipMonitor::add_wheels(Timestamp time, double distance) {
  if (!wheels_.empty() && time <= wheels_.back().time) return;
  wheels_.push_back({time, distance});
  while (wheels_.size() > 2 && (time - wheels_.front().time).seconds() > kHistorySeconds) wheels_.pop_front();
  judge();
}

bool WheelSlipMonitor::wheel_distance_at(Timestamp time, double& distance) const {
  if (wheels_.size() < 2 || time < wheels_.front().time || time > wheels_.back().time) return false;
  for (std::size_t i = 1; i < wheels_.size(); ++i) {
    if (wheels_[i].time < time) continue;
    const WheelSample& a = wheels_[i - 1];
    const WheelSample& b = wheels_[i];
    const double span = (b.time - a.time).seconds();
    const double fraction = span > 0.0 ? (time - a.time).seconds() / span : 1.0;
    distance = a.distance + fraction * (b.distance - a.distance);
    return true;
  }
  return false;
}

void WheelSlipMonitor::add_lidar_motion(Timestamp from, Timestamp to, double forward, bool reliable) {
  if (!(to > from) || !std::isfinite(forward)) return;
  motions_.push_back({from, to, forward, reliable});
  while (!motions_.empty() && (to - motions_.front().from).seconds() > config_.window_s + 1e-9) motions_.pop_front();
  judge();
}

void WheelSlipMonitor::judge() {
  // Once per LiDAR motion, as soon as the wheels cover its window (a sweep can be registered
  // before the wheel messages of its time arrive, or after).
  if (motions_.empty() || motions_.back().to <= judged_until_) return;
  const Timestamp start = motions_.front().from;
  const Timestamp to = motions_.back().to;
  if ((to - start).seconds() < 0.8 * config_.window_s) return;  // not enough of the window yet
  double lidar = 0.0;
  for (std::size_t i = 0; i < motions_.size(); ++i) {
    if (!motions_[i].reliable) return;
    if (i > 0 && motions_[i].from != motions_[i - 1].to) return;  // a sweep missing: not judged
    lidar += motions_[i].forward;
  }
  double wheels_start = 0.0, wheels_end = 0.0;
  if (!wheel_distance_at(start, wheels_start)) return;
  if (!wheel_distance_at(to, wheels_end)) return;  // the wheels have not reached it yet
  judged_until_ = to;
  last_difference_ = (wheels_end - wheels_start) - lidar;
  const bool disagree = std::abs(last_difference_) > config_.absolute_tolerance_m + config_.relative_tolerance * std::abs(lidar);
  if (disagree) {
    if (!slipping_) ++episodes_;
    slipping_ = true;
    last_disagreement_ = to;
  } else if (slipping_ && (to - last_disagreement_).seconds() >= config_.recovery_s) {
    slipping_ = false;
  }
}

}  // namespace hanzo::fusion::pipeline
