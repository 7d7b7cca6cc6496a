#pragma once
// IMU propagation: the process model every frontend filter shares. The IMU is the control
// input; the state (navigation_state.hpp) is integrated from one IMU sample to the next with
// the sample held constant over the interval (zero-order hold):
//
//   w = C R_body_imu (w_m - bg),  C = diag(1, 1, 1/c)   body angular velocity (c: gyro_yaw_scale)
//   f = R_body_imu (f_m - ba) - w x (w x p_body_imu)   specific force at the body origin
//   p' = p + v dt + 1/2 (Rm f + g) dt^2,   v' = v + (Rm f + g) dt,   R' = R Exp(w dt)
// with Rm = R Exp(w dt / 2), the attitude at the interval's middle: the force turns with the body
// over the interval (R alone leaves an error of first order in dt; bench/RESULTS.md).
//
// The lever-arm term with the angular acceleration (dw/dt x p_body_imu) is left out: it needs
// the derivative of a noisy gyro and is negligible for IMUs within ~0.3 m of the body origin.
//
// Error-state transition (right perturbation, navigation_state.hpp), first order in dt
// (Sola, "Quaternion kinematics for the error-state Kalman filter" (2017), eq. 269-270 adapted
// to a gravity state and a body-to-IMU rotation):
//   dv'     = dv - R [Em f]x dt dtheta - R Em R_body_imu dt dba + dt dg,   Em = Exp(w dt / 2)
//   dtheta' = Exp(w dt)^T dtheta - Jr(w dt) C R_body_imu dt dbg - Jr(w dt) e_z (w_z / c) dt dc
//   dp'     = dp + dt dv + dt/2 (velocity terms above)
//
// Noise. The spec's process_noise_accel / _gyro are the standard deviations of ONE sample at
// the IMU rate (as the simulator draws them), i.e. white noise of density sigma^2 * sample
// interval; the bias random walks are densities in unit/sqrt(s). Per step of length dt:
//   Q_v = sigma_a^2 T_s dt,  Q_theta = sigma_g^2 T_s dt,  Q_ba = rw_a^2 dt,  Q_bg = rw_g^2 dt,
// so splitting an interval (a GNSS fix between two IMU samples) adds the same noise.

#include <Eigen/Core>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/estimate/navigation_state.hpp"

namespace hanzo::fusion::estimate {

/// One IMU reading in the IMU's own axes.
struct ImuSample {
  Timestamp timestamp;
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();     // rad/s
  Eigen::Vector3d linear_acceleration = Eigen::Vector3d::Zero();  // m/s^2, specific force
};

/// Where the IMU sits on the body (calibration's "imu_to_body" = T_body_imu).
struct ImuMounting {
  SO3 R_body_imu;
  Eigen::Vector3d p_body_imu = Eigen::Vector3d::Zero();  // m, IMU origin in the body frame

  static ImuMounting from_transform(const SE3& T_body_imu) { return {T_body_imu.rotation(), T_body_imu.translation()}; }
};

/// Noise of the process model; the spec's configuration names and units.
struct ImuNoise {
  double process_noise_accel = 0.1;       // m/s^2, std of one accelerometer sample
  double process_noise_gyro = 0.01;       // rad/s, std of one gyroscope sample
  double accel_bias_random_walk = 0.001;  // m/s^2/sqrt(s)
  double gyro_bias_random_walk = 0.0001;  // rad/s/sqrt(s)
  double sample_interval = 0.005;         // s, 1 / IMU rate (turns per-sample stds into densities)
  /// 1/sqrt(s): how fast the wheel speed scale may drift (load, tyre pressure); 0 without wheels.
  double wheel_scale_random_walk = 0.0;
  /// 1/sqrt(s): how fast the gyro's yaw-rate scale may drift (temperature); 0 where not estimated.
  double gyro_yaw_scale_random_walk = 0.0;
  /// rad/m/sqrt(s): how fast the wheels' heading drift may change (load); 0 where not estimated.
  double wheel_heading_drift_random_walk = 0.0;
};

/// The body angular velocity w = C R_body_imu (angular_velocity_imu - bg) (see the header
/// comment), and when wanted its derivatives by the gyro bias (3x3) and by the yaw scale c (3x1).
Eigen::Vector3d body_angular_velocity(const NavigationState& state, const Eigen::Vector3d& angular_velocity_imu,
                                      const SO3& R_body_imu, Eigen::Matrix3d* by_gyro_bias = nullptr,
                                      Eigen::Vector3d* by_yaw_scale = nullptr);

/// Bias-corrected angular velocity and specific force at the body origin, body axes.
struct BodyMotion {
  Eigen::Vector3d angular_velocity = Eigen::Vector3d::Zero();  // rad/s
  Eigen::Vector3d specific_force = Eigen::Vector3d::Zero();    // m/s^2
};

BodyMotion body_motion(const NavigationState& state, const ImuSample& sample, const ImuMounting& mounting);

/// The non-identity blocks of the error-state transition of one step (see the header comment).
struct ImuTransition {
  double dt = 0.0;
  Eigen::Matrix3d velocity_by_orientation = Eigen::Matrix3d::Zero();     // -R [Em f]x dt
  Eigen::Matrix3d velocity_by_accel_bias = Eigen::Matrix3d::Zero();      // -R Em R_body_imu dt
  Eigen::Matrix3d orientation_by_orientation = Eigen::Matrix3d::Identity();  // Exp(w dt)^T
  Eigen::Matrix3d orientation_by_gyro_bias = Eigen::Matrix3d::Zero();    // -Jr(w dt) C R_body_imu dt
  Eigen::Vector3d orientation_by_yaw_scale = Eigen::Vector3d::Zero();    // -Jr(w dt) e_z (w_z / c) dt
};

/// Integrates the nominal state over dt >= 0 seconds (timestamp advanced by dt) and fills the
/// transition blocks when transition is given.
NavigationState propagate_state(const NavigationState& state, const BodyMotion& motion, double dt,
                                const ImuMounting& mounting, ImuTransition* transition);

/// The full transition matrix Phi built from the blocks (for tests and reference code).
ErrorCovariance transition_matrix(const ImuTransition& transition);

/// The discrete process noise Q of one step of length dt (see the header comment).
ErrorCovariance process_noise(const ImuNoise& noise, double dt);

/// covariance <- Phi covariance Phi^T + Q, exploiting the sparsity of Phi (about 5x fewer
/// multiplications than the dense product). Result symmetric.
void propagate_covariance(ErrorCovariance& covariance, const ImuTransition& transition, const ImuNoise& noise);

/// M <- M Phi^T for any number of rows, with the same sparse column operations.
template <int Rows>
void multiply_by_transition_transpose(Eigen::Matrix<double, Rows, kErrorStateDimension>& M, const ImuTransition& t) {
  using Columns = Eigen::Matrix<double, Rows, 3>;
  const Columns velocity = M.template middleCols<3>(kVelocityIndex) +
                           M.template middleCols<3>(kOrientationIndex) * t.velocity_by_orientation.transpose() +
                           M.template middleCols<3>(kAccelBiasIndex) * t.velocity_by_accel_bias.transpose() +
                           t.dt * M.template middleCols<3>(kGravityIndex);
  const Columns orientation = M.template middleCols<3>(kOrientationIndex) * t.orientation_by_orientation.transpose() +
                              M.template middleCols<3>(kGyroBiasIndex) * t.orientation_by_gyro_bias.transpose() +
                              M.col(kGyroYawScaleIndex) * t.orientation_by_yaw_scale.transpose();
  // dp' = dp + dt/2 (dv + dv').
  M.template middleCols<3>(kPositionIndex) += 0.5 * t.dt * (M.template middleCols<3>(kVelocityIndex) + velocity);
  M.template middleCols<3>(kVelocityIndex) = velocity;
  M.template middleCols<3>(kOrientationIndex) = orientation;
}

}  // namespace hanzo::fusion::estimate
