#include "hanzo/fusion/estimate/navigation_state.hpp"

#include <cmath>

namespace hanzo::fusion::estimate {

NavigationState NavigationState::plus(const ErrorVector& delta) const {
  NavigationState out = *this;
  out.position += delta.segment<3>(kPositionIndex);
  out.R_world_body = R_world_body * SO3::exp(delta.segment<3>(kOrientationIndex));
  out.velocity += delta.segment<3>(kVelocityIndex);
  out.accel_bias += delta.segment<3>(kAccelBiasIndex);
  out.gyro_bias += delta.segment<3>(kGyroBiasIndex);
  out.gravity += delta.segment<3>(kGravityIndex);
  out.wheel_speed_scale += delta(kWheelScaleIndex);
  out.gyro_yaw_scale += delta(kGyroYawScaleIndex);
  out.wheel_heading_drift += delta(kWheelHeadingDriftIndex);
  return out;
}

ErrorVector NavigationState::minus(const NavigationState& other) const {
  ErrorVector delta;
  delta.segment<3>(kPositionIndex) = position - other.position;
  delta.segment<3>(kOrientationIndex) = (other.R_world_body.inverse() * R_world_body).log();
  delta.segment<3>(kVelocityIndex) = velocity - other.velocity;
  delta.segment<3>(kAccelBiasIndex) = accel_bias - other.accel_bias;
  delta.segment<3>(kGyroBiasIndex) = gyro_bias - other.gyro_bias;
  delta.segment<3>(kGravityIndex) = gravity - other.gravity;
  delta(kWheelScaleIndex) = wheel_speed_scale - other.wheel_speed_scale;
  delta(kGyroYawScaleIndex) = gyro_yaw_scale - other.gyro_yaw_scale;
  delta(kWheelHeadingDriftIndex) = wheel_heading_drift - other.wheel_heading_drift;
  return delta;
}

bool NavigationState::all_finite() const {
  return position.allFinite() && R_world_body.quaternion().coeffs().allFinite() && velocity.allFinite() &&
         accel_bias.allFinite() && gyro_bias.allFinite() && gravity.allFinite() &&
         std::isfinite(wheel_speed_scale) && std::isfinite(gyro_yaw_scale) && gyro_yaw_scale > 0.0 &&
         std::isfinite(wheel_heading_drift);
}

void symmetrize(ErrorCovariance& covariance) {
  covariance = 0.5 * (covariance + covariance.transpose()).eval();
}

}  // namespace hanzo::fusion::estimate
