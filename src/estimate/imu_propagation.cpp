#include "hanzo/fusion/estimate/imu_propagation.hpp"

namespace hanzo::fusion::estimate {

Eigen::Vector3d body_angular_velocity(const NavigationState& state, const Eigen::Vector3d& angular_velocity_imu,
                                      const SO3& R_body_imu, Eigen::Matrix3d* by_gyro_bias, Eigen::Vector3d* by_yaw_scale) {
  Eigen::Vector3d w = R_body_imu * (angular_velocity_imu - state.gyro_bias);
  w.z() /= state.gyro_yaw_scale;
  if (by_gyro_bias != nullptr) {
    *by_gyro_bias = -R_body_imu.matrix();
    by_gyro_bias->row(2) /= state.gyro_yaw_scale;
  }
  if (by_yaw_scale != nullptr) *by_yaw_scale = Eigen::Vector3d(0.0, 0.0, -w.z() / state.gyro_yaw_scale);
  return w;
}

BodyMotion body_motion(const NavigationState& state, const ImuSample& sample, const ImuMounting& mounting) {
  BodyMotion motion;
  motion.angular_velocity = body_angular_velocity(state, sample.angular_velocity, mounting.R_body_imu);
  const Eigen::Vector3d& w = motion.angular_velocity;
  motion.specific_force =
      mounting.R_body_imu * (sample.linear_acceleration - state.accel_bias) - w.cross(w.cross(mounting.p_body_imu));
  return motion;
}

NavigationState propagate_state(const NavigationState& state, const BodyMotion& motion, double dt,
                                const ImuMounting& mounting, ImuTransition* transition) {
  const Eigen::Matrix3d R = state.R_world_body.matrix();
  const Eigen::Vector3d rotation_vector = motion.angular_velocity * dt;
  SO3::Jacobian right_jacobian;
  const SO3 delta_rotation = SO3::exp(rotation_vector, &right_jacobian);
  // The specific force acts at the interval's mid attitude R Exp(w dt / 2).
  const Eigen::Matrix3d half_rotation = SO3::exp(0.5 * rotation_vector).matrix();
  const Eigen::Vector3d force_at_mid_attitude = half_rotation * motion.specific_force;
  const Eigen::Vector3d acceleration = R * force_at_mid_attitude + state.gravity;

  NavigationState next = state;
  next.timestamp = state.timestamp + Duration::from_seconds(dt);
  next.position = state.position + state.velocity * dt + 0.5 * acceleration * dt * dt;
  next.velocity = state.velocity + acceleration * dt;
  next.R_world_body = state.R_world_body * delta_rotation;

  if (transition != nullptr) {
    transition->dt = dt;
    transition->velocity_by_orientation = -R * SO3::hat(force_at_mid_attitude) * dt;
    transition->velocity_by_accel_bias = -R * half_rotation * mounting.R_body_imu.matrix() * dt;
    transition->orientation_by_orientation = delta_rotation.matrix().transpose();
    // dw/dbg = -C R_body_imu and dw/dc = -e_z w_z / c (w = motion.angular_velocity, already divided by c).
    Eigen::Matrix3d by_gyro_bias = -mounting.R_body_imu.matrix();
    by_gyro_bias.row(2) /= state.gyro_yaw_scale;
    transition->orientation_by_gyro_bias = right_jacobian * by_gyro_bias * dt;
    transition->orientation_by_yaw_scale =
        right_jacobian * Eigen::Vector3d(0.0, 0.0, -motion.angular_velocity.z() / state.gyro_yaw_scale) * dt;
  }
  return next;
}

ErrorCovariance transition_matrix(const ImuTransition& t) {
  ErrorCovariance phi = ErrorCovariance::Identity();
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  phi.block<3, 3>(kPositionIndex, kOrientationIndex) = 0.5 * t.dt * t.velocity_by_orientation;
  phi.block<3, 3>(kPositionIndex, kVelocityIndex) = t.dt * I;
  phi.block<3, 3>(kPositionIndex, kAccelBiasIndex) = 0.5 * t.dt * t.velocity_by_accel_bias;
  phi.block<3, 3>(kPositionIndex, kGravityIndex) = 0.5 * t.dt * t.dt * I;
  phi.block<3, 3>(kOrientationIndex, kOrientationIndex) = t.orientation_by_orientation;
  phi.block<3, 3>(kOrientationIndex, kGyroBiasIndex) = t.orientation_by_gyro_bias;
  phi.block<3, 1>(kOrientationIndex, kGyroYawScaleIndex) = t.orientation_by_yaw_scale;
  phi.block<3, 3>(kVelocityIndex, kOrientationIndex) = t.velocity_by_orientation;
  phi.block<3, 3>(kVelocityIndex, kAccelBiasIndex) = t.velocity_by_accel_bias;
  phi.block<3, 3>(kVelocityIndex, kGravityIndex) = t.dt * I;
  return phi;
}

ErrorCovariance process_noise(const ImuNoise& noise, double dt) {
  ErrorCovariance q = ErrorCovariance::Zero();
  const double velocity_density = noise.process_noise_accel * noise.process_noise_accel * noise.sample_interval;
  const double angle_density = noise.process_noise_gyro * noise.process_noise_gyro * noise.sample_interval;
  const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
  // White acceleration noise integrated twice: the classic [dt^3/3, dt^2/2; dt^2/2, dt] blocks.
  q.block<3, 3>(kPositionIndex, kPositionIndex) = velocity_density * dt * dt * dt / 3.0 * I;
  q.block<3, 3>(kPositionIndex, kVelocityIndex) = velocity_density * dt * dt / 2.0 * I;
  q.block<3, 3>(kVelocityIndex, kPositionIndex) = velocity_density * dt * dt / 2.0 * I;
  q.block<3, 3>(kVelocityIndex, kVelocityIndex) = velocity_density * dt * I;
  q.block<3, 3>(kOrientationIndex, kOrientationIndex) = angle_density * dt * I;
  q.block<3, 3>(kAccelBiasIndex, kAccelBiasIndex) = noise.accel_bias_random_walk * noise.accel_bias_random_walk * dt * I;
  q.block<3, 3>(kGyroBiasIndex, kGyroBiasIndex) = noise.gyro_bias_random_walk * noise.gyro_bias_random_walk * dt * I;
  q(kWheelScaleIndex, kWheelScaleIndex) = noise.wheel_scale_random_walk * noise.wheel_scale_random_walk * dt;
  q(kGyroYawScaleIndex, kGyroYawScaleIndex) = noise.gyro_yaw_scale_random_walk * noise.gyro_yaw_scale_random_walk * dt;
  q(kWheelHeadingDriftIndex, kWheelHeadingDriftIndex) = noise.wheel_heading_drift_random_walk * noise.wheel_heading_drift_random_walk * dt;
  return q;
}

void propagate_covariance(ErrorCovariance& P, const ImuTransition& t, const ImuNoise& noise) {
  using Rows = Eigen::Matrix<double, 3, kErrorStateDimension>;
  const double dt = t.dt;
  // A = Phi P: only the position, orientation and velocity rows change.
  const Rows velocity_rows = P.middleRows<3>(kVelocityIndex) +
                             t.velocity_by_orientation * P.middleRows<3>(kOrientationIndex) +
                             t.velocity_by_accel_bias * P.middleRows<3>(kAccelBiasIndex) +
                             dt * P.middleRows<3>(kGravityIndex);
  const Rows orientation_rows = t.orientation_by_orientation * P.middleRows<3>(kOrientationIndex) +
                                t.orientation_by_gyro_bias * P.middleRows<3>(kGyroBiasIndex) +
                                t.orientation_by_yaw_scale * P.row(kGyroYawScaleIndex);
  // dp' = dp + dt/2 (dv + dv'): the position row is the mean of the old and new velocity rows.
  P.middleRows<3>(kPositionIndex) += 0.5 * dt * (P.middleRows<3>(kVelocityIndex) + velocity_rows);
  P.middleRows<3>(kVelocityIndex) = velocity_rows;
  P.middleRows<3>(kOrientationIndex) = orientation_rows;
  // Phi P Phi^T = A Phi^T: the same operations on the columns.
  multiply_by_transition_transpose(P, t);

  const double velocity_density = noise.process_noise_accel * noise.process_noise_accel * noise.sample_interval;
  const double angle_density = noise.process_noise_gyro * noise.process_noise_gyro * noise.sample_interval;
  const double accel_walk = noise.accel_bias_random_walk * noise.accel_bias_random_walk * dt;
  const double gyro_walk = noise.gyro_bias_random_walk * noise.gyro_bias_random_walk * dt;
  for (int axis = 0; axis < 3; ++axis) {
    P(kPositionIndex + axis, kPositionIndex + axis) += velocity_density * dt * dt * dt / 3.0;
    P(kPositionIndex + axis, kVelocityIndex + axis) += velocity_density * dt * dt / 2.0;
    P(kVelocityIndex + axis, kPositionIndex + axis) += velocity_density * dt * dt / 2.0;
    P(kVelocityIndex + axis, kVelocityIndex + axis) += velocity_density * dt;
    P(kOrientationIndex + axis, kOrientationIndex + axis) += angle_density * dt;
    P(kAccelBiasIndex + axis, kAccelBiasIndex + axis) += accel_walk;
    P(kGyroBiasIndex + axis, kGyroBiasIndex + axis) += gyro_walk;
  }
  P(kWheelScaleIndex, kWheelScaleIndex) += noise.wheel_scale_random_walk * noise.wheel_scale_random_walk * dt;
  P(kGyroYawScaleIndex, kGyroYawScaleIndex) += noise.gyro_yaw_scale_random_walk * noise.gyro_yaw_scale_random_walk * dt;
  P(kWheelHeadingDriftIndex, kWheelHeadingDriftIndex) += noise.wheel_heading_drift_random_walk * noise.wheel_heading_drift_random_walk * dt;
}

}  // namespace hanzo::fusion::estimate
