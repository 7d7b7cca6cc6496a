#pragma once
// Factors of visual/LiDAR-inertial graphs: the IMU preintegration factor between two
// keyframes, the bias random walk between their biases, and the navigation factors that anchor
// them (GPS position with lever arm, gravity: attitude from a static accelerometer and a prior
// on a gravity vector, velocity and bias priors).
//
// Variables: X(i) = T_world_imu (SE3, tangent (translation, rotation), right perturbation:
// p + R d_rho, R Exp(d_phi)), V(i) world velocity m/s, B(i) ImuBias. All residuals are
// whitened by their noise; Jacobians are analytic and checked numerically in the tests.
//
// ImuFactor (Forster et al. 2017, eq. 45), keys X(i), V(i), X(j), V(j), B(i), with the
// preintegrated deltas corrected for b_i (imu_preintegration.hpp), residual order
// (rotation, velocity, position) as the preintegration's covariance:
//   r_R = Log(dR(b_i)^T R_i^T R_j)
//   r_v = R_i^T (v_j - v_i - g T) - dv(b_i)
//   r_p = R_i^T (p_j - p_i - v_i T - 1/2 g T^2) - dp(b_i)
// Jacobians (appendix B), Jr^-1 = Jr^-1(r_R):
//   r_R: phi_i -Jr^-1 R_j^T R_i, phi_j Jr^-1, bg -Jr^-1 Exp(r_R)^T Jr(dR/dbg dbg) dR/dbg
//   r_v: phi_i [R_i^T (v_j - v_i - g T)]x, v_i -R_i^T, v_j R_i^T, ba -dv/dba, bg -dv/dbg
//   r_p: rho_i -I, phi_i [R_i^T (p_j - p_i - v_i T - 1/2 g T^2)]x, rho_j R_i^T R_j,
//        v_i -R_i^T T, ba -dp/dba, bg -dp/dbg

#include <memory>

#include "hanzo/fusion/graph/factor.hpp"
#include "hanzo/fusion/graph/imu_preintegration.hpp"

namespace hanzo::fusion::graph {

class ImuFactor final : public Factor {
 public:
  /// Fails when the preintegration holds no sample or its covariance is not positive definite
  /// (zero IMU noise).
  static Result<std::shared_ptr<ImuFactor>> create(Key pose_i, Key velocity_i, Key pose_j, Key velocity_j, Key bias_i,
                                                   ImuPreintegration preintegration);
  int dimension() const override { return 9; }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;
  const ImuPreintegration& preintegration() const { return preintegration_; }

 private:
  ImuFactor(std::vector<Key> keys, ImuPreintegration preintegration, GaussianNoise noise)
      : Factor(std::move(keys)), preintegration_(std::move(preintegration)), noise_(std::move(noise)) {}
  ImuPreintegration preintegration_;
  GaussianNoise noise_;
};

/// Biases drift as random walks between keyframes i and j, dt seconds apart:
/// r = b_j - b_i with standard deviations random_walk * sqrt(dt) (the spec's
/// accel_bias_random_walk m/s^2/sqrt(s) and gyro_bias_random_walk rad/s/sqrt(s)).
class ImuBiasRandomWalkFactor final : public Factor {
 public:
  /// Fails unless dt and both random walks are finite and > 0.
  static Result<std::shared_ptr<ImuBiasRandomWalkFactor>> create(Key bias_i, Key bias_j, double dt, double accel_bias_random_walk,
                                                                 double gyro_bias_random_walk);
  int dimension() const override { return 6; }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

 private:
  ImuBiasRandomWalkFactor(Key bias_i, Key bias_j, Eigen::Matrix<double, 6, 1> inverse_sigmas)
      : Factor({bias_i, bias_j}), inverse_sigmas_(std::move(inverse_sigmas)) {}
  Eigen::Matrix<double, 6, 1> inverse_sigmas_;
};

/// A GNSS antenna position in the world frame (ENU metres, geodesy.hpp converts fixes) for the
/// pose X(i) whose frame holds the antenna at lever_arm: r = p + R lever_arm - z; noise 3x3
/// (the fix's covariance). Jacobians: rho R, phi -R [lever_arm]x.
/// With an error key E(j) (a Vector3d: the receiver's slowly varying position error in units of
/// error_scale, a unit-variance GaussMarkovFactor process) the fix measures the antenna plus that
/// error: r = p + R lever_arm + S e - z, Jacobian e S, S = error_scale (world ENU m, e.g. the
/// Cholesky factor of the fix's correlated covariance); the noise is then the fix's white part.
class GpsFactor final : public Factor {
 public:
  GpsFactor(Key pose, const Eigen::Vector3d& position_world, const Eigen::Vector3d& lever_arm, GaussianNoise noise)
      : Factor({pose}), position_world_(position_world), lever_arm_(lever_arm), noise_(std::move(noise)) {}
  GpsFactor(Key pose, Key error, const Eigen::Matrix3d& error_scale, const Eigen::Vector3d& position_world, const Eigen::Vector3d& lever_arm,
            GaussianNoise noise)
      : Factor({pose, error}), position_world_(position_world), lever_arm_(lever_arm), error_scale_(error_scale), noise_(std::move(noise)) {}
  int dimension() const override { return 3; }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

 private:
  Eigen::Vector3d position_world_;
  Eigen::Vector3d lever_arm_;
  Eigen::Matrix3d error_scale_ = Eigen::Matrix3d::Identity();
  GaussianNoise noise_;
};

/// A first-order Gauss-Markov process x(t) (dx/dt = -x / tau + w) between its values at two
/// times dt apart, for a Vector3d variable (a GNSS receiver's position error: multipath and the
/// atmosphere change over seconds to minutes): r = x_j - a x_i, a = exp(-dt / tau), with the
/// covariance (1 - a^2) Sigma for the process's stationary covariance Sigma (Maybeck,
/// Stochastic Models, Estimation and Control, vol. 1, sec. 4.11). Jacobians: x_i -a I, x_j I.
class GaussMarkovFactor final : public Factor {
 public:
  /// Fails unless dt >= 0 and tau > 0 are finite and Sigma is positive definite.
  static Result<std::shared_ptr<GaussMarkovFactor>> create(Key value_i, Key value_j, double dt, double tau,
                                                           const Eigen::Matrix3d& stationary_covariance);
  int dimension() const override { return 3; }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;
  double decay() const { return decay_; }

 private:
  GaussMarkovFactor(Key value_i, Key value_j, double decay, GaussianNoise noise)
      : Factor({value_i, value_j}), decay_(decay), noise_(std::move(noise)) {}
  double decay_;
  GaussianNoise noise_;
};

/// The velocity of a sensor rigidly mounted on the body, in the sensor's axes (a radar's ego
/// velocity from its targets' Doppler, wheel odometry's forward speed with the non-holonomic
/// lateral and vertical zeros), for X(i) = T_world_body and V(i) (world m/s):
///   r = R_bs^T (R^T v + w x p_bs) - z
/// with (R_bs, p_bs) = T_body_sensor and w the body's angular rate (body axes, rad/s; from the
/// gyro, held fixed). Noise 3x3 (m/s)^2 in sensor axes. Jacobians: phi R_bs^T [R^T v]x,
/// v R_bs^T R^T, rho 0.
class BodyVelocityFactor final : public Factor {
 public:
  BodyVelocityFactor(Key pose, Key velocity, const Eigen::Vector3d& velocity_sensor, const SE3& T_body_sensor,
                     const Eigen::Vector3d& angular_rate_body, GaussianNoise noise)
      : Factor({pose, velocity}), velocity_sensor_(velocity_sensor), R_sensor_body_(T_body_sensor.rotation().matrix().transpose()),
        lever_velocity_body_(angular_rate_body.cross(T_body_sensor.translation())), noise_(std::move(noise)) {}
  int dimension() const override { return 3; }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

 private:
  Eigen::Vector3d velocity_sensor_;
  Eigen::Matrix3d R_sensor_body_;
  Eigen::Vector3d lever_velocity_body_;  // w x p_bs
  GaussianNoise noise_;
};

/// Attitude from a static accelerometer (the IMU at rest measures the specific force of
/// gravity alone): r = R^T (-g_world) - f_measured on the pose X(i) = T_world_imu, noise 3x3.
/// It fixes roll and pitch (the direction of gravity in the IMU frame), never yaw. Jacobian:
/// phi [R^T (-g_world)]x, rho 0.
class GravityFactor final : public Factor {
 public:
  GravityFactor(Key pose, const Eigen::Vector3d& specific_force, GaussianNoise noise,
                const Eigen::Vector3d& gravity_world = Eigen::Vector3d(0.0, 0.0, -9.80665))
      : Factor({pose}), specific_force_(specific_force), gravity_world_(gravity_world), noise_(std::move(noise)) {}
  int dimension() const override { return 3; }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

 private:
  Eigen::Vector3d specific_force_;
  Eigen::Vector3d gravity_world_;
  GaussianNoise noise_;
};

/// Prior on a gravity vector variable G (world frame m/s^2, for a world frame not aligned with
/// gravity, e.g. a visual-inertial map): its magnitude and its direction, 4 residuals
///   r = ((|G| - magnitude) / magnitude_sigma, (G / |G| - direction) / direction_sigma).
/// Jacobian: d|G|/dG = n^T, d(G/|G|)/dG = (I - n n^T) / |G| with n = G / |G|. Fails to
/// evaluate at G = 0.
class GravityPriorFactor final : public Factor {
 public:
  /// direction: unit vector (normalized here); sigmas > 0.
  GravityPriorFactor(Key gravity, double magnitude, const Eigen::Vector3d& direction, double magnitude_sigma, double direction_sigma)
      : Factor({gravity}), magnitude_(magnitude), direction_(direction.normalized()), magnitude_sigma_(magnitude_sigma),
        direction_sigma_(direction_sigma) {}
  int dimension() const override { return 4; }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

 private:
  double magnitude_;
  Eigen::Vector3d direction_;
  double magnitude_sigma_;
  double direction_sigma_;
};

/// Prior on a Euclidean variable (a velocity Vector3d or an ImuBias): r = x - prior.
template <typename Vector>
class EuclideanPriorFactor final : public Factor {
 public:
  EuclideanPriorFactor(Key key, const Vector& prior, GaussianNoise noise) : Factor({key}), prior_(prior), noise_(std::move(noise)) {}
  int dimension() const override { return noise_.dimension(); }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override;

 private:
  Vector prior_;
  GaussianNoise noise_;
};

using PriorFactorVector3 = EuclideanPriorFactor<Eigen::Vector3d>;
using PriorFactorImuBias = EuclideanPriorFactor<ImuBias>;

}  // namespace hanzo::fusion::graph
