#pragma once
// ImuSpikeFilter: rejects single IMU samples that jump impossibly far from the previous
// accepted one (electrical spikes, saturation glitches), the IMU's counterpart of the
// chi-square gate of the other sensors. The change between consecutive samples is compared,
// per axis, with what the white noise plus a physical limit on how fast the motion can change
// allows:
//   |a_k - a_prev| > gate_sigmas * sqrt(2 sigma_a^2 + (max_jerk dt)^2)         or
//   |w_k - w_prev| > gate_sigmas * sqrt(2 sigma_g^2 + (max_angular_acceleration dt)^2).
// After max_consecutive rejections in a row the motion really changed (an impact): the sample
// is accepted and becomes the new reference.

#include "hanzo/fusion/estimate/imu_propagation.hpp"

namespace hanzo::fusion::estimate {

struct ImuSpikeFilterConfig {
  double gate_sigmas = 6.0;
  double max_jerk = 500.0;                  // m/s^3
  double max_angular_acceleration = 200.0;  // rad/s^2
  int max_consecutive = 5;
};

class ImuSpikeFilter {
 public:
  ImuSpikeFilter(const ImuSpikeFilterConfig& config, const ImuNoise& noise) : config_(config), noise_(noise) {}
  /// True when the sample is plausible (and becomes the reference), false for a spike.
  bool accept(const ImuSample& sample);

 private:
  ImuSpikeFilterConfig config_;
  ImuNoise noise_;
  bool has_reference_ = false;
  ImuSample reference_;
  int consecutive_rejections_ = 0;
};

}  // namespace hanzo::fusion::estimate
