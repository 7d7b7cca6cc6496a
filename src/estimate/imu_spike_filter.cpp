#include "hanzo/fusion/estimate/imu_spike_filter.hpp"

#include <cmath>

namespace hanzo::fusion::estimate {

bool ImuSpikeFilter::accept(const ImuSample& sample) {
  if (has_reference_ && consecutive_rejections_ < config_.max_consecutive) {
    const double dt = std::max(0.0, (sample.timestamp - reference_.timestamp).seconds());
    const double accel_limit =
        config_.gate_sigmas * std::hypot(std::sqrt(2.0) * noise_.process_noise_accel, config_.max_jerk * dt);
    const double gyro_limit =
        config_.gate_sigmas * std::hypot(std::sqrt(2.0) * noise_.process_noise_gyro, config_.max_angular_acceleration * dt);
    const bool spike = (sample.linear_acceleration - reference_.linear_acceleration).cwiseAbs().maxCoeff() > accel_limit ||
                       (sample.angular_velocity - reference_.angular_velocity).cwiseAbs().maxCoeff() > gyro_limit;
    if (spike) {
      ++consecutive_rejections_;
      return false;
    }
  }
  reference_ = sample;
  has_reference_ = true;
  consecutive_rejections_ = 0;
  return true;
}

}  // namespace hanzo::fusion::estimate
