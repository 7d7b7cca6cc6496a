#include "hanzo/fusion/graph/imu_factors.hpp"

#include <cmath>

#include <fmt/format.h>

namespace hanzo::fusion::graph {
namespace {

Eigen::VectorXd stacked(const Eigen::Vector3d& value) { return value; }
Eigen::VectorXd stacked(const ImuBias& value) { return value.vector(); }

}  // namespace

Result<std::shared_ptr<ImuFactor>> ImuFactor::create(Key pose_i, Key velocity_i, Key pose_j, Key velocity_j, Key bias_i,
                                                     ImuPreintegration preintegration) {
  if (preintegration.sample_count() == 0) return Error("imu factor: the preintegration holds no IMU sample");
  Result<GaussianNoise> noise = GaussianNoise::from_covariance(preintegration.covariance());
  if (!noise) return Error("imu factor: the preintegrated covariance is not positive definite (is the IMU noise zero?)");
  return std::shared_ptr<ImuFactor>(
      new ImuFactor({pose_i, velocity_i, pose_j, velocity_j, bias_i}, std::move(preintegration), std::move(*noise)));
}

Result<Eigen::VectorXd> ImuFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  SE3 T_i, T_j;
  Eigen::Vector3d v_i, v_j;
  ImuBias bias;
  HANZO_ASSIGN_OR_RETURN(T_i, values.at<SE3>(keys()[0]));
  HANZO_ASSIGN_OR_RETURN(v_i, values.at<Eigen::Vector3d>(keys()[1]));
  HANZO_ASSIGN_OR_RETURN(T_j, values.at<SE3>(keys()[2]));
  HANZO_ASSIGN_OR_RETURN(v_j, values.at<Eigen::Vector3d>(keys()[3]));
  HANZO_ASSIGN_OR_RETURN(bias, values.at<ImuBias>(keys()[4]));
  const ImuPreintegration& pim = preintegration_;
  const ImuDeltas delta = pim.corrected(bias);
  const double T = pim.delta_time();
  const Eigen::Vector3d& g = pim.config().gravity;
  const Eigen::Matrix3d R_i_transpose = T_i.rotation().matrix().transpose();
  const Eigen::Vector3d velocity_change = R_i_transpose * (v_j - v_i - g * T);
  const Eigen::Vector3d position_change = R_i_transpose * (T_j.translation() - T_i.translation() - v_i * T - 0.5 * g * T * T);
  const SO3 rotation_error = delta.rotation.inverse() * T_i.rotation().inverse() * T_j.rotation();
  Eigen::Matrix<double, 9, 1> r;
  r << rotation_error.log(), velocity_change - delta.velocity, position_change - delta.position;
  const Eigen::MatrixXd& U = noise_.sqrt_information();
  if (jacobians != nullptr) {
    const Eigen::Vector3d r_R = r.head<3>();
    const Eigen::Matrix3d Jr_inverse = SO3::right_jacobian_inverse(r_R);
    const Eigen::Vector3d gyro_change = bias.gyroscope - pim.bias_estimate().gyroscope;
    const Eigen::Matrix3d& rotation_by_gyro = pim.rotation_by_gyro_bias();
    const Eigen::Matrix3d I = Eigen::Matrix3d::Identity();
    Eigen::Matrix<double, 9, 6> J_pose_i = Eigen::Matrix<double, 9, 6>::Zero();
    J_pose_i.block<3, 3>(0, 3) = -Jr_inverse * T_j.rotation().matrix().transpose() * T_i.rotation().matrix();
    J_pose_i.block<3, 3>(3, 3) = SO3::hat(velocity_change);
    J_pose_i.block<3, 3>(6, 0) = -I;
    J_pose_i.block<3, 3>(6, 3) = SO3::hat(position_change);
    Eigen::Matrix<double, 9, 3> J_velocity_i = Eigen::Matrix<double, 9, 3>::Zero();
    J_velocity_i.block<3, 3>(3, 0) = -R_i_transpose;
    J_velocity_i.block<3, 3>(6, 0) = -R_i_transpose * T;
    Eigen::Matrix<double, 9, 6> J_pose_j = Eigen::Matrix<double, 9, 6>::Zero();
    J_pose_j.block<3, 3>(0, 3) = Jr_inverse;
    J_pose_j.block<3, 3>(6, 0) = R_i_transpose * T_j.rotation().matrix();
    Eigen::Matrix<double, 9, 3> J_velocity_j = Eigen::Matrix<double, 9, 3>::Zero();
    J_velocity_j.block<3, 3>(3, 0) = R_i_transpose;
    Eigen::Matrix<double, 9, 6> J_bias = Eigen::Matrix<double, 9, 6>::Zero();
    J_bias.block<3, 3>(0, 3) = -Jr_inverse * SO3::exp(r_R).matrix().transpose() *
                               SO3::right_jacobian(rotation_by_gyro * gyro_change) * rotation_by_gyro;
    J_bias.block<3, 3>(3, 0) = -pim.velocity_by_accel_bias();
    J_bias.block<3, 3>(3, 3) = -pim.velocity_by_gyro_bias();
    J_bias.block<3, 3>(6, 0) = -pim.position_by_accel_bias();
    J_bias.block<3, 3>(6, 3) = -pim.position_by_gyro_bias();
    *jacobians = {U * J_pose_i, U * J_velocity_i, U * J_pose_j, U * J_velocity_j, U * J_bias};
  }
  return Eigen::VectorXd(U * r);
}

Result<std::shared_ptr<ImuBiasRandomWalkFactor>> ImuBiasRandomWalkFactor::create(Key bias_i, Key bias_j, double dt,
                                                                                 double accel_bias_random_walk, double gyro_bias_random_walk) {
  if (!(dt > 0.0) || !std::isfinite(dt) || !(accel_bias_random_walk > 0.0) || !std::isfinite(accel_bias_random_walk) ||
      !(gyro_bias_random_walk > 0.0) || !std::isfinite(gyro_bias_random_walk)) {
    return Error(fmt::format("imu bias random walk: dt ({}) and both random walks ({}, {}) must be finite and > 0", dt,
                             accel_bias_random_walk, gyro_bias_random_walk));
  }
  Eigen::Matrix<double, 6, 1> inverse_sigmas;
  inverse_sigmas << Eigen::Vector3d::Constant(1.0 / (accel_bias_random_walk * std::sqrt(dt))),
      Eigen::Vector3d::Constant(1.0 / (gyro_bias_random_walk * std::sqrt(dt)));
  return std::shared_ptr<ImuBiasRandomWalkFactor>(new ImuBiasRandomWalkFactor(bias_i, bias_j, inverse_sigmas));
}

Result<Eigen::VectorXd> ImuBiasRandomWalkFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  ImuBias b_i, b_j;
  HANZO_ASSIGN_OR_RETURN(b_i, values.at<ImuBias>(keys()[0]));
  HANZO_ASSIGN_OR_RETURN(b_j, values.at<ImuBias>(keys()[1]));
  if (jacobians != nullptr) {
    const Eigen::MatrixXd W = inverse_sigmas_.asDiagonal();
    *jacobians = {-W, W};
  }
  return Eigen::VectorXd(inverse_sigmas_.cwiseProduct(b_j.vector() - b_i.vector()));
}

Result<Eigen::VectorXd> GpsFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  SE3 T;
  HANZO_ASSIGN_OR_RETURN(T, values.at<SE3>(keys()[0]));
  const Eigen::Matrix3d R = T.rotation().matrix();
  Eigen::Vector3d r = T.translation() + R * lever_arm_ - position_world_;
  if (keys().size() == 2) {
    Eigen::Vector3d error;
    HANZO_ASSIGN_OR_RETURN(error, values.at<Eigen::Vector3d>(keys()[1]));
    r += error_scale_ * error;
  }
  const Eigen::MatrixXd& U = noise_.sqrt_information();
  if (jacobians != nullptr) {
    Eigen::Matrix<double, 3, 6> J;
    J << R, -R * SO3::hat(lever_arm_);
    *jacobians = {U * J};
    if (keys().size() == 2) jacobians->push_back(U * error_scale_);
  }
  return Eigen::VectorXd(U * r);
}

Result<std::shared_ptr<GaussMarkovFactor>> GaussMarkovFactor::create(Key value_i, Key value_j, double dt, double tau,
                                                                     const Eigen::Matrix3d& stationary_covariance) {
  if (!std::isfinite(dt) || dt < 0.0 || !std::isfinite(tau) || !(tau > 0.0)) {
    return Error(fmt::format("Gauss-Markov factor: dt {} must be >= 0 and tau {} > 0", dt, tau));
  }
  const double decay = std::exp(-dt / tau);
  // dt = 0 would make the process noise zero: the values are then equal up to a tiny variance.
  const double variance_scale = std::max(1.0 - decay * decay, 1e-9);
  Result<GaussianNoise> noise = GaussianNoise::from_covariance(variance_scale * stationary_covariance);
  if (!noise) return Error(fmt::format("Gauss-Markov factor: {}", noise.error().message));
  return std::shared_ptr<GaussMarkovFactor>(new GaussMarkovFactor(value_i, value_j, decay, std::move(*noise)));
}

Result<Eigen::VectorXd> GaussMarkovFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  Eigen::Vector3d x_i, x_j;
  HANZO_ASSIGN_OR_RETURN(x_i, values.at<Eigen::Vector3d>(keys()[0]));
  HANZO_ASSIGN_OR_RETURN(x_j, values.at<Eigen::Vector3d>(keys()[1]));
  const Eigen::MatrixXd& U = noise_.sqrt_information();
  if (jacobians != nullptr) *jacobians = {-decay_ * U, U};
  return Eigen::VectorXd(U * (x_j - decay_ * x_i));
}

Result<Eigen::VectorXd> BodyVelocityFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  SE3 T;
  Eigen::Vector3d velocity_world;
  HANZO_ASSIGN_OR_RETURN(T, values.at<SE3>(keys()[0]));
  HANZO_ASSIGN_OR_RETURN(velocity_world, values.at<Eigen::Vector3d>(keys()[1]));
  const Eigen::Matrix3d R_body_world = T.rotation().matrix().transpose();
  const Eigen::Vector3d velocity_body = R_body_world * velocity_world;
  const Eigen::MatrixXd& U = noise_.sqrt_information();
  if (jacobians != nullptr) {
    Eigen::Matrix<double, 3, 6> J_pose = Eigen::Matrix<double, 3, 6>::Zero();
    J_pose.rightCols<3>() = R_sensor_body_ * SO3::hat(velocity_body);
    *jacobians = {U * J_pose, U * R_sensor_body_ * R_body_world};
  }
  return Eigen::VectorXd(U * (R_sensor_body_ * (velocity_body + lever_velocity_body_) - velocity_sensor_));
}

Result<Eigen::VectorXd> GravityFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  SE3 T;
  HANZO_ASSIGN_OR_RETURN(T, values.at<SE3>(keys()[0]));
  const Eigen::Vector3d predicted = T.rotation().inverse() * (-gravity_world_);
  const Eigen::MatrixXd& U = noise_.sqrt_information();
  if (jacobians != nullptr) {
    Eigen::Matrix<double, 3, 6> J = Eigen::Matrix<double, 3, 6>::Zero();
    J.rightCols<3>() = SO3::hat(predicted);
    *jacobians = {U * J};
  }
  return Eigen::VectorXd(U * (predicted - specific_force_));
}

Result<Eigen::VectorXd> GravityPriorFactor::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  Eigen::Vector3d G;
  HANZO_ASSIGN_OR_RETURN(G, values.at<Eigen::Vector3d>(keys()[0]));
  const double norm = G.norm();
  if (!(norm > 0.0)) return Error(fmt::format("gravity prior on {}: the gravity vector is zero", key_to_string(keys()[0])));
  const Eigen::Vector3d n = G / norm;
  Eigen::Vector4d r;
  r << (norm - magnitude_) / magnitude_sigma_, (n - direction_) / direction_sigma_;
  if (jacobians != nullptr) {
    Eigen::Matrix<double, 4, 3> J;
    J.row(0) = n.transpose() / magnitude_sigma_;
    J.bottomRows<3>() = (Eigen::Matrix3d::Identity() - n * n.transpose()) / (norm * direction_sigma_);
    *jacobians = {J};
  }
  return Eigen::VectorXd(r);
}

template <typename Vector>
Result<Eigen::VectorXd> EuclideanPriorFactor<Vector>::evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const {
  Vector value;
  HANZO_ASSIGN_OR_RETURN(value, values.at<Vector>(keys()[0]));
  const Eigen::MatrixXd& U = noise_.sqrt_information();
  if (U.cols() != stacked(value).size()) return Error(fmt::format("prior on {}: noise of the wrong dimension", key_to_string(keys()[0])));
  if (jacobians != nullptr) *jacobians = {U};
  return Eigen::VectorXd(U * (stacked(value) - stacked(prior_)));
}

template class EuclideanPriorFactor<Eigen::Vector3d>;
template class EuclideanPriorFactor<ImuBias>;

}  // namespace hanzo::fusion::graph
