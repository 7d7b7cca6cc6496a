#pragma once
// IMU preintegration between two keyframes: Forster, Carlone, Dellaert, Scaramuzza, "On-Manifold
// Preintegration for Real-Time Visual-Inertial Odometry", IEEE T-RO 33(1), 2017. The many IMU
// samples between keyframes i and j become one relative motion measurement (imu_factors.hpp)
// that does not depend on the states at i and j, and that is corrected to first order when the
// bias estimate changes, so the optimizer never re-integrates.
//
// Frames and units: the deltas are in the IMU frame at keyframe i; inputs are specific force
// (m/s^2) and angular velocity (rad/s) in IMU axes, each held constant over its dt (seconds).
//
// With the bias estimate b- = (ba, bg) the deltas follow (discrete eq. 33-35 of the paper):
//   dR_{k+1} = dR_k Exp((w_k - bg) dt)
//   dv_{k+1} = dv_k + dR_k (a_k - ba) dt
//   dp_{k+1} = dp_k + dv_k dt + 1/2 dR_k (a_k - ba) dt^2
// and relate the states at i and j as (eq. 38, gravity g in the world frame):
//   R_j = R_i dR,   v_j = v_i + g T + R_i dv,   p_j = p_i + v_i T + 1/2 g T^2 + R_i dp.
//
// Covariance of the deltas' noise, order (rotation, velocity, position), eq. 62-63:
//   Sigma' = A Sigma A^T + B Sigma_a B^T + C Sigma_g C^T,
//   A = [Exp(w dt)^T, 0, 0;  -dR [a]x dt, I, 0;  -1/2 dR [a]x dt^2, I dt, I],
//   B = [0; dR dt; 1/2 dR dt^2],   C = [Jr(w dt) dt; 0; 0]   (a, w bias-corrected).
// Noise magnitudes use the spec's names and meaning (as estimate/imu_propagation.hpp):
// process_noise_accel / _gyro are standard deviations of ONE sample at the IMU rate, i.e. a
// white-noise density sigma^2 * sample_interval, so a sample held dt has covariance
// sigma^2 * sample_interval / dt; splitting an interval adds the same noise.
//
// Bias Jacobians (appendix A, eq. 69-70), accumulated with the deltas:
//   dR/dbg' = Exp(w dt)^T dR/dbg - Jr(w dt) dt
//   dv/dba' = dv/dba - dR dt,          dv/dbg' = dv/dbg - dR [a]x dR/dbg dt
//   dp/dba' = dp/dba + dv/dba dt - 1/2 dR dt^2,
//   dp/dbg' = dp/dbg + dv/dbg dt - 1/2 dR [a]x dR/dbg dt^2
// and the first-order correction for a bias b = b- + db (eq. 44):
//   dR(b) = dR Exp(dR/dbg dbg),  dv(b) = dv + dv/dba dba + dv/dbg dbg,  likewise dp.

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/graph/values.hpp"

namespace hanzo::fusion::graph {

struct ImuPreintegrationConfig {
  double process_noise_accel = 0.1;   ///< m/s^2, standard deviation of one accelerometer sample
  double process_noise_gyro = 0.01;   ///< rad/s, standard deviation of one gyroscope sample
  double sample_interval = 0.005;     ///< s, 1 / IMU rate (turns per-sample sigmas into densities)
  Eigen::Vector3d gravity{0.0, 0.0, -9.80665};  ///< world frame, m/s^2 (ENU: down)
};

/// The preintegrated deltas (or their bias-corrected values): IMU frame at keyframe i.
struct ImuDeltas {
  SO3 rotation;                                             ///< dR_ij
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();       ///< dv_ij, m/s
  Eigen::Vector3d position = Eigen::Vector3d::Zero();       ///< dp_ij, m
};

class ImuPreintegration {
 public:
  using Matrix9d = Eigen::Matrix<double, 9, 9>;

  /// Starts empty (identity deltas, zero covariance) at the bias estimate b-.
  ImuPreintegration(const ImuPreintegrationConfig& config, const ImuBias& bias_estimate);

  /// Adds one sample held over dt seconds. Fails, leaving the preintegration unchanged, on a
  /// non-finite reading or dt not in (0, 1] s (a gap that long is a lost IMU, not a sample).
  Status integrate(const Eigen::Vector3d& specific_force, const Eigen::Vector3d& angular_velocity, double dt);

  int sample_count() const { return sample_count_; }
  double delta_time() const { return delta_time_; }  ///< T = t_j - t_i, seconds
  const ImuDeltas& deltas() const { return deltas_; }
  const Matrix9d& covariance() const { return covariance_; }  ///< (rotation, velocity, position)
  const ImuBias& bias_estimate() const { return bias_estimate_; }
  const ImuPreintegrationConfig& config() const { return config_; }

  const Eigen::Matrix3d& rotation_by_gyro_bias() const { return rotation_by_gyro_bias_; }
  const Eigen::Matrix3d& velocity_by_accel_bias() const { return velocity_by_accel_bias_; }
  const Eigen::Matrix3d& velocity_by_gyro_bias() const { return velocity_by_gyro_bias_; }
  const Eigen::Matrix3d& position_by_accel_bias() const { return position_by_accel_bias_; }
  const Eigen::Matrix3d& position_by_gyro_bias() const { return position_by_gyro_bias_; }

  /// The deltas corrected to first order for another bias (eq. 44).
  ImuDeltas corrected(const ImuBias& bias) const;

  /// The pose (T_world_imu) and world velocity at j predicted from those at i (eq. 38 with the
  /// deltas corrected for `bias`).
  void predict(const SE3& T_world_i, const Eigen::Vector3d& velocity_i, const ImuBias& bias, SE3* T_world_j,
               Eigen::Vector3d* velocity_j) const;

 private:
  ImuPreintegrationConfig config_;
  ImuBias bias_estimate_;
  int sample_count_ = 0;
  double delta_time_ = 0.0;
  ImuDeltas deltas_;
  Matrix9d covariance_ = Matrix9d::Zero();
  Eigen::Matrix3d rotation_by_gyro_bias_ = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d velocity_by_accel_bias_ = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d velocity_by_gyro_bias_ = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d position_by_accel_bias_ = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d position_by_gyro_bias_ = Eigen::Matrix3d::Zero();
};

}  // namespace hanzo::fusion::graph
