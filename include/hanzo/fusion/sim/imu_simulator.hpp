#pragma once
// ImuSimulator: IMU measurements along a SplineTrajectory, with the noise model of the spec's
// fusion configuration (config/fusion_config.hpp, `imu:` section):
//
//   accelerometer = R_world_imu^T (a_imu - g_world) + accel_bias + n_a,  n_a ~ N(0, process_noise_accel^2)
//   gyroscope     = K omega_imu + gyro_bias + n_g,                        n_g ~ N(0, process_noise_gyro^2)
//                   (K = diag(gyro_scale_factor): the gyro's scale error per IMU axis, 1 = none)
//   bias_{k+1}    = bias_k + N(0, random_walk^2 * dt)   (random walks in unit/s/sqrt(Hz) = unit/sqrt(s))
//
// g_world = (0, 0, -gravity) in ENU, so a level IMU at rest reads (0, 0, +gravity). The IMU sits
// at T_body_imu on the body: its acceleration includes the lever-arm terms
// alpha x r + omega x (omega x r) (alpha by a central difference of the spline's angular
// velocity over +-1 ms). Deterministic for a given seed.

#include <cstdint>
#include <optional>
#include <random>
#include <string>

#include <Eigen/Core>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"

namespace hanzo::fusion::sim {

struct ImuSimulatorConfig {
  double rate_hz = 200.0;
  double gravity = 9.81;                   ///< m/s^2
  double process_noise_accel = 0.1;        ///< m/s^2, white noise std per sample
  double process_noise_gyro = 0.01;        ///< rad/s, white noise std per sample
  double accel_bias_random_walk = 0.001;   ///< m/s^2/sqrt(Hz)
  double gyro_bias_random_walk = 0.0001;   ///< rad/s/sqrt(Hz)
  Eigen::Vector3d initial_accel_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d initial_gyro_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_scale_factor = Eigen::Vector3d::Ones();  ///< reading per true rate, IMU axes
  SE3 T_body_imu;                          ///< mounting (identity: the IMU is the body frame)
  std::string frame_id = "imu";
  uint64_t seed = 1;
};

/// One simulated sample and the truth behind it.
struct ImuSample {
  msgs::ImuMessage message;
  Eigen::Vector3d accel_bias;  ///< true bias in this sample
  Eigen::Vector3d gyro_bias;
};

class ImuSimulator {
 public:
  explicit ImuSimulator(ImuSimulatorConfig config);

  /// The noiseless measurement (specific force, angular rate in the IMU frame) at `time`.
  static void ideal_measurement(const SplineTrajectory& trajectory, Timestamp time, const ImuSimulatorConfig& config,
                                Eigen::Vector3d& specific_force, Eigen::Vector3d& angular_rate);
  /// The sample at `time`; call in increasing time order (the biases walk over the time
  /// since the previous call).
  ImuSample measure(const SplineTrajectory& trajectory, Timestamp time);
  /// Samples at rate_hz from the trajectory's start to its end, noise and biases drawn in order.
  std::vector<ImuSample> simulate(const SplineTrajectory& trajectory);

 private:
  Eigen::Vector3d noise(double sigma);

  ImuSimulatorConfig config_;
  std::mt19937_64 random_;
  Eigen::Vector3d accel_bias_;
  Eigen::Vector3d gyro_bias_;
  std::optional<Timestamp> previous_time_;
};

}  // namespace hanzo::fusion::sim
