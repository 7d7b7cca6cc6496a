// IMU preintegration and the inertial factors: noiseless deltas against the simulator's
// trajectory, bias Jacobians against re-integration, the propagated covariance against Monte
// Carlo, every factor Jacobian against numerical differentiation, and a GPS + IMU graph that
// recovers the trajectory and the biases.

#include <cmath>
#include <random>
#include <variant>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "graph/jacobian_check.hpp"

#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/imu_factors.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"
#include "hanzo/fusion/sim/imu_simulator.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"

namespace hanzo::fusion::graph {
namespace {

using ::testing::HasSubstr;

const Timestamp kStart = Timestamp::from_nanoseconds(1'700'000'000'000'000'000);
constexpr double kGravity = 9.80665;

// A 6-DOF path turning, rolling and climbing (the simulator's test trajectory, scaled).
sim::SplineTrajectory wavy_trajectory() {
  std::vector<SE3> poses;
  for (int i = 0; i < 32; ++i) {
    const double a = 0.35 * i;
    poses.emplace_back(SO3::exp({0.3 * std::sin(a), 0.2 * std::cos(1.3 * a), a}),
                       Eigen::Vector3d(8.0 * std::cos(a), 8.0 * std::sin(a), 1.0 + 0.5 * std::sin(2.0 * a)));
  }
  return *sim::SplineTrajectory::create(kStart, Duration::from_milliseconds(500), poses);
}

// A figure eight with changing speed, yawing and tilting like a drone: accelerations that change
// direction in the body frame, which keep yaw and accelerometer bias apart (on a circle at
// constant speed they trade off).
sim::SplineTrajectory figure_eight_trajectory() {
  std::vector<SE3> poses;
  for (int i = 0; i < 64; ++i) {
    const double a = 0.3 * i;
    poses.emplace_back(SO3::exp({0.2 * std::sin(1.7 * a), 0.15 * std::cos(1.1 * a), 0.8 * std::sin(0.7 * a)}),
                       Eigen::Vector3d(10.0 * std::sin(a), 6.0 * std::sin(2.0 * a), 1.0 + 0.5 * std::sin(3.0 * a)));
  }
  return *sim::SplineTrajectory::create(kStart, Duration::from_milliseconds(500), poses);
}

sim::ImuSimulatorConfig noiseless_imu() {
  sim::ImuSimulatorConfig config;
  config.gravity = kGravity;
  config.process_noise_accel = config.process_noise_gyro = 0.0;
  config.accel_bias_random_walk = config.gyro_bias_random_walk = 0.0;
  return config;
}

// Integrates [begin, end) in steps of dt with the noiseless measurement at each step's middle.
ImuPreintegration preintegrate_truth(const sim::SplineTrajectory& trajectory, double begin, double end, double dt,
                                     const ImuBias& bias_estimate, const ImuBias& true_bias = {}) {
  ImuPreintegration preintegration(ImuPreintegrationConfig{}, bias_estimate);
  const auto steps = static_cast<int>(std::lround((end - begin) / dt));
  for (int k = 0; k < steps; ++k) {
    Eigen::Vector3d specific_force, angular_velocity;
    sim::ImuSimulator::ideal_measurement(trajectory, kStart + Duration::from_seconds(begin + (k + 0.5) * dt), noiseless_imu(),
                                         specific_force, angular_velocity);
    EXPECT_TRUE(preintegration.integrate(specific_force + true_bias.accelerometer, angular_velocity + true_bias.gyroscope, dt).ok());
  }
  return preintegration;
}

TEST(ImuPreintegration, NoiselessDeltasPredictTheTrajectory) {
  const sim::SplineTrajectory trajectory = wavy_trajectory();
  for (double begin = 1.0; begin < 12.0; begin += 2.5) {
    const ImuPreintegration preintegration = preintegrate_truth(trajectory, begin, begin + 1.0, 0.001, ImuBias{});
    EXPECT_EQ(preintegration.sample_count(), 1000);
    EXPECT_NEAR(preintegration.delta_time(), 1.0, 1e-9);
    const sim::TrajectorySample i = trajectory.sample(kStart + Duration::from_seconds(begin));
    const sim::TrajectorySample j = trajectory.sample(kStart + Duration::from_seconds(begin + 1.0));
    SE3 predicted;
    Eigen::Vector3d predicted_velocity;
    preintegration.predict(i.T_world_body, i.velocity_world, ImuBias{}, &predicted, &predicted_velocity);
    EXPECT_LT((predicted.translation() - j.T_world_body.translation()).norm(), 1e-3) << begin;
    EXPECT_LT((predicted_velocity - j.velocity_world).norm(), 3e-3) << begin;  // first order in dt
    EXPECT_LT((predicted.rotation().inverse() * j.T_world_body.rotation()).angle(), 1e-5) << begin;
  }
}

TEST(ImuPreintegration, BiasJacobiansMatchReintegration) {
  const sim::SplineTrajectory trajectory = wavy_trajectory();
  const ImuBias estimate{{0.05, -0.02, 0.1}, {0.01, 0.003, -0.02}};
  const ImuPreintegration base = preintegrate_truth(trajectory, 2.0, 3.0, 0.005, estimate);
  // Central differences of re-integrated deltas in each bias component.
  constexpr double h = 1e-5;
  for (int k = 0; k < 6; ++k) {
    Eigen::Matrix<double, 6, 1> step = Eigen::Matrix<double, 6, 1>::Zero();
    step(k) = h;
    const ImuDeltas plus = preintegrate_truth(trajectory, 2.0, 3.0, 0.005, ImuBias::from_vector(estimate.vector() + step)).deltas();
    const ImuDeltas minus = preintegrate_truth(trajectory, 2.0, 3.0, 0.005, ImuBias::from_vector(estimate.vector() - step)).deltas();
    const Eigen::Vector3d rotation = (minus.rotation.inverse() * plus.rotation).log() / (2 * h);
    const Eigen::Vector3d velocity = (plus.velocity - minus.velocity) / (2 * h);
    const Eigen::Vector3d position = (plus.position - minus.position) / (2 * h);
    const bool accel = k < 3;
    const int axis = k % 3;
    const Eigen::Vector3d expected_rotation = accel ? Eigen::Vector3d::Zero() : Eigen::Vector3d(base.rotation_by_gyro_bias().col(axis));
    const Eigen::Vector3d expected_velocity = accel ? base.velocity_by_accel_bias().col(axis) : base.velocity_by_gyro_bias().col(axis);
    const Eigen::Vector3d expected_position = accel ? base.position_by_accel_bias().col(axis) : base.position_by_gyro_bias().col(axis);
    EXPECT_LT((rotation - expected_rotation).norm(), 1e-5) << k;
    EXPECT_LT((velocity - expected_velocity).norm(), 1e-5) << k;
    EXPECT_LT((position - expected_position).norm(), 1e-5) << k;
  }
  // The first-order correction is close for a small bias change, exact for the accelerometer.
  const ImuBias changed{{0.06, -0.01, 0.09}, {0.011, 0.002, -0.019}};
  const ImuDeltas corrected = base.corrected(changed);
  const ImuDeltas reintegrated = preintegrate_truth(trajectory, 2.0, 3.0, 0.005, changed).deltas();
  EXPECT_LT((corrected.position - reintegrated.position).norm(), 1e-5);
  EXPECT_LT((corrected.velocity - reintegrated.velocity).norm(), 1e-5);
  EXPECT_LT((corrected.rotation.inverse() * reintegrated.rotation).angle(), 1e-6);
}

TEST(ImuPreintegration, PropagatedCovarianceMatchesMonteCarlo) {
  const sim::SplineTrajectory trajectory = wavy_trajectory();
  ImuPreintegrationConfig config;
  config.process_noise_accel = 0.2;
  config.process_noise_gyro = 0.02;
  config.sample_interval = 0.01;
  const ImuPreintegration truth = preintegrate_truth(trajectory, 3.0, 4.0, 0.01, ImuBias{});
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> measurements;
  for (int k = 0; k < 100; ++k) {
    Eigen::Vector3d specific_force, angular_velocity;
    sim::ImuSimulator::ideal_measurement(trajectory, kStart + Duration::from_seconds(3.0 + (k + 0.5) * 0.01), noiseless_imu(),
                                         specific_force, angular_velocity);
    measurements.emplace_back(specific_force, angular_velocity);
  }
  std::mt19937_64 random(3);
  std::normal_distribution<double> normal(0.0, 1.0);
  const auto noise = [&](double sigma) { return Eigen::Vector3d(sigma * normal(random), sigma * normal(random), sigma * normal(random)); };
  constexpr int kRuns = 2000;
  ImuPreintegration::Matrix9d sample_covariance = ImuPreintegration::Matrix9d::Zero();
  ImuPreintegration last(config, ImuBias{});
  for (int run = 0; run < kRuns; ++run) {
    ImuPreintegration noisy(config, ImuBias{});
    for (const auto& [specific_force, angular_velocity] : measurements) {
      ASSERT_TRUE(noisy.integrate(specific_force + noise(0.2), angular_velocity + noise(0.02), 0.01).ok());
    }
    Eigen::Matrix<double, 9, 1> error;
    error << (truth.deltas().rotation.inverse() * noisy.deltas().rotation).log(), noisy.deltas().velocity - truth.deltas().velocity,
        noisy.deltas().position - truth.deltas().position;
    sample_covariance += error * error.transpose() / kRuns;
    last = noisy;
  }
  // Each variance within 15 % (the sampling error of 2000 runs is about 3 %), correlations too.
  const ImuPreintegration::Matrix9d& propagated = last.covariance();
  for (int k = 0; k < 9; ++k) {
    EXPECT_NEAR(sample_covariance(k, k) / propagated(k, k), 1.0, 0.15) << k;
  }
  int strong_correlations = 0;
  for (int a = 0; a < 9; ++a) {
    for (int b = a + 1; b < 9; ++b) {
      const double propagated_correlation = propagated(a, b) / std::sqrt(propagated(a, a) * propagated(b, b));
      const double sample_correlation = sample_covariance(a, b) / std::sqrt(sample_covariance(a, a) * sample_covariance(b, b));
      EXPECT_NEAR(sample_correlation, propagated_correlation, 0.1) << a << ", " << b;
      if (std::abs(propagated_correlation) > 0.3) ++strong_correlations;
    }
  }
  EXPECT_GT(strong_correlations, 3);  // velocity-position and rotation-velocity couplings exist
}

TEST(ImuPreintegration, RejectsBadSamples) {
  ImuPreintegration preintegration(ImuPreintegrationConfig{}, ImuBias{});
  const Eigen::Vector3d nan = Eigen::Vector3d::Constant(std::nan(""));
  EXPECT_THAT(preintegration.integrate(nan, Eigen::Vector3d::Zero(), 0.01).error().message, HasSubstr("non-finite"));
  EXPECT_THAT(preintegration.integrate(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), 0.0).error().message, HasSubstr("(0, 1]"));
  EXPECT_FALSE(preintegration.integrate(Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), -0.01).ok());
  EXPECT_EQ(preintegration.sample_count(), 0);
  EXPECT_THAT(ImuFactor::create(X(0), V(0), X(1), V(1), B(0), preintegration).error().message, HasSubstr("no IMU sample"));
  EXPECT_FALSE(ImuBiasRandomWalkFactor::create(B(0), B(1), 0.0, 1e-3, 1e-4).ok());
  EXPECT_THAT(GaussMarkovFactor::create(E(0), E(1), -1.0, 5.0, Eigen::Matrix3d::Identity()).error().message, HasSubstr("dt"));
  EXPECT_FALSE(GaussMarkovFactor::create(E(0), E(1), 1.0, 0.0, Eigen::Matrix3d::Identity()).ok());
  EXPECT_FALSE(GaussMarkovFactor::create(E(0), E(1), 1.0, 5.0, Eigen::Matrix3d::Zero()).ok());
}

TEST(ImuFactors, JacobiansMatchNumericalDifferentiation) {
  const sim::SplineTrajectory trajectory = wavy_trajectory();
  const ImuBias estimate{{0.05, -0.02, 0.1}, {0.01, 0.003, -0.02}};
  ImuPreintegration preintegration = preintegrate_truth(trajectory, 4.0, 4.5, 0.005, estimate);
  const std::shared_ptr<ImuFactor> imu = ImuFactor::create(X(0), V(0), X(1), V(1), B(0), preintegration).value();
  const auto walk = ImuBiasRandomWalkFactor::create(B(0), B(1), 0.5, 1e-3, 1e-4).value();
  const GpsFactor gps(X(1), {1.0, 2.0, 3.0}, {0.3, -0.2, 0.8}, GaussianNoise::from_sigmas(Eigen::Vector3d(0.5, 0.4, 1.0)).value());
  const PriorFactorVector3 velocity_prior(V(0), {1.0, 0.0, 0.2}, GaussianNoise::from_sigmas(Eigen::Vector3d::Constant(0.3)).value());
  const PriorFactorImuBias bias_prior(B(1), estimate, GaussianNoise::from_sigmas(Eigen::VectorXd::Constant(6, 0.1)).value());
  std::mt19937 random(5);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (int trial = 0; trial < 5; ++trial) {
    // States off the truth (big residuals) and a bias away from the linearization point.
    const sim::TrajectorySample i = trajectory.sample(kStart + Duration::from_seconds(4.0));
    const sim::TrajectorySample j = trajectory.sample(kStart + Duration::from_seconds(4.5));
    const auto jitter = [&](double scale) { return Eigen::Vector3d(scale * normal(random), scale * normal(random), scale * normal(random)); };
    Values values;
    values.insert(X(0), SE3(i.T_world_body.rotation() * SO3::exp(jitter(0.3)), i.T_world_body.translation() + jitter(1.0)));
    values.insert(X(1), SE3(j.T_world_body.rotation() * SO3::exp(jitter(0.3)), j.T_world_body.translation() + jitter(1.0)));
    values.insert(V(0), Eigen::Vector3d(i.velocity_world + jitter(1.0)));
    values.insert(V(1), Eigen::Vector3d(j.velocity_world + jitter(1.0)));
    values.insert(B(0), ImuBias{estimate.accelerometer + jitter(0.1), estimate.gyroscope + jitter(0.05)});
    values.insert(B(1), ImuBias{jitter(0.1), jitter(0.05)});
    expect_jacobians_match(*imu, values);
    expect_jacobians_match(*walk, values);
    expect_jacobians_match(gps, values);
    Values with_errors = values;
    with_errors.insert(E(0), jitter(0.5));
    with_errors.insert(E(1), jitter(0.5));
    expect_jacobians_match(GpsFactor(X(1), E(1), Eigen::Vector3d(0.3, 0.4, 0.6).asDiagonal(), {1.0, 2.0, 3.0}, {0.3, -0.2, 0.8}, GaussianNoise::from_sigmas(Eigen::Vector3d(0.05, 0.04, 0.1)).value()),
                           with_errors);
    const SE3 T_body_radar(SO3::exp(Eigen::Vector3d(0.1, -0.3, 0.5)), Eigen::Vector3d(3.6, 0.2, 0.5));
    expect_jacobians_match(BodyVelocityFactor(X(0), V(0), {8.0, 0.3, -0.1}, T_body_radar, {0.02, -0.01, 0.3},
                                              GaussianNoise::from_sigmas(Eigen::Vector3d(0.1, 0.2, 0.3)).value()),
                           values);
    expect_jacobians_match(*GaussMarkovFactor::create(E(0), E(1), 0.4, 5.0, Eigen::Matrix3d::Identity()).value(), with_errors);
    expect_jacobians_match(velocity_prior, values);
    expect_jacobians_match(bias_prior, values);
    const GravityFactor gravity(X(0), jitter(1.0) + Eigen::Vector3d(0.0, 0.0, 9.8), GaussianNoise::from_sigmas(Eigen::Vector3d::Constant(0.05)).value());
    expect_jacobians_match(gravity, values);
    Values with_gravity = values;
    with_gravity.insert(L(0), Eigen::Vector3d(jitter(1.0) + Eigen::Vector3d(0.0, 0.0, -9.8)));
    expect_jacobians_match(GravityPriorFactor(L(0), 9.81, {0.0, 0.1, -1.0}, 0.05, 0.02), with_gravity);
  }
  // At the truth with the true (estimate) bias the IMU residual is tiny against its noise.
  Values truth;
  const sim::TrajectorySample i = trajectory.sample(kStart + Duration::from_seconds(4.0));
  const sim::TrajectorySample j = trajectory.sample(kStart + Duration::from_seconds(4.5));
  truth.insert(X(0), i.T_world_body);
  truth.insert(X(1), j.T_world_body);
  truth.insert(V(0), i.velocity_world);
  truth.insert(V(1), j.velocity_world);
  truth.insert(B(0), estimate);
  const auto noiseless_truth = preintegrate_truth(trajectory, 4.0, 4.5, 0.001, estimate, estimate);
  EXPECT_LT(ImuFactor::create(X(0), V(0), X(1), V(1), B(0), noiseless_truth).value()->evaluate(truth, nullptr).value().norm(), 0.5);
}

// A static IMU tilted by roll 0.2, pitch -0.1: gravity factors alone recover roll and pitch and
// leave yaw where it started (unobservable); a gravity vector prior pulls a free vector to 9.81
// along its direction. A zero gravity vector is refused.
TEST(ImuFactors, GravityFactorsFixTiltNotYaw) {
  const SO3 R_world_imu = SO3::exp({0.0, 0.0, 0.7}) * SO3::exp({0.0, -0.1, 0.0}) * SO3::exp({0.2, 0.0, 0.0});
  const Eigen::Vector3d gravity(0.0, 0.0, -9.80665);
  const Eigen::Vector3d at_rest = R_world_imu.inverse() * (-gravity);
  FactorGraph graph;
  graph.emplace<GravityFactor>(X(0), at_rest, GaussianNoise::from_sigmas(Eigen::Vector3d::Constant(0.02)).value(), gravity);
  graph.emplace<PriorFactorSE3>(X(0), SE3(SO3::exp({0.0, 0.0, 0.3}), Eigen::Vector3d::Zero()),
                                GaussianNoise::from_sigmas((Eigen::VectorXd(6) << 0.1, 0.1, 0.1, 10.0, 10.0, 10.0).finished()).value());
  graph.emplace<GravityPriorFactor>(L(0), 9.81, Eigen::Vector3d(0.0, 0.0, -1.0), 0.01, 0.01);
  Values values;
  values.insert(X(0), SE3(SO3::exp({0.0, 0.0, 0.3}), Eigen::Vector3d::Zero()));  // level, yaw 0.3
  values.insert(L(0), Eigen::Vector3d(1.0, -2.0, -5.0));
  ASSERT_TRUE(optimize(graph, values).ok());
  const SO3 estimate = values.at<SE3>(X(0)).value().rotation();
  EXPECT_LT((estimate.inverse() * Eigen::Vector3d(gravity) - R_world_imu.inverse() * gravity).norm(), 1e-6);  // tilt exact
  EXPECT_LT(std::abs(std::atan2(estimate.matrix()(1, 0), estimate.matrix()(0, 0)) - 0.3), 0.05);        // yaw kept
  EXPECT_LT((values.at<Eigen::Vector3d>(L(0)).value() - Eigen::Vector3d(0.0, 0.0, -9.81)).norm(), 1e-4);
  Values zero;
  zero.insert(L(0), Eigen::Vector3d::Zero());
  EXPECT_THAT(GravityPriorFactor(L(0), 9.81, {0.0, 0.0, -1.0}, 0.01, 0.01).evaluate(zero, nullptr).error().message, HasSubstr("zero"));
}

// Keyframes every 0.5 s along 28 s of a figure eight: IMU factors from a noisy 200 Hz IMU with
// constant biases, GPS fixes (0.3 m) at every keyframe through a lever arm, weak priors at the
// start. From a start 0.5 m / 6 deg off with zero biases, the batch solution recovers the
// trajectory better than the GPS alone and estimates both biases.
TEST(ImuFactors, GpsAndImuGraphRecoversTrajectoryAndBiases) {
  const sim::SplineTrajectory trajectory = figure_eight_trajectory();
  sim::ImuSimulatorConfig imu_config = noiseless_imu();
  imu_config.process_noise_accel = 0.05;
  imu_config.process_noise_gyro = 0.003;
  imu_config.initial_accel_bias = {0.12, -0.08, 0.05};
  imu_config.initial_gyro_bias = {0.01, -0.006, 0.004};
  imu_config.seed = 9;
  sim::ImuSimulator imu(imu_config);
  ImuPreintegrationConfig config;
  config.process_noise_accel = imu_config.process_noise_accel;
  config.process_noise_gyro = imu_config.process_noise_gyro;
  config.sample_interval = 1.0 / imu_config.rate_hz;
  const Eigen::Vector3d lever_arm(0.3, 0.0, 0.6);

  std::mt19937_64 random(21);
  std::normal_distribution<double> normal(0.0, 1.0);
  const auto noise = [&](double sigma) { return Eigen::Vector3d(sigma * normal(random), sigma * normal(random), sigma * normal(random)); };
  constexpr int kKeyframes = 57;
  constexpr int kSamplesPerKeyframe = 100;  // 0.5 s at 200 Hz
  FactorGraph graph;
  Values values;
  std::vector<sim::TrajectorySample> truth;
  const GaussianNoise gps_noise = GaussianNoise::from_sigmas(Eigen::Vector3d::Constant(0.3)).value();
  ImuPreintegration preintegration(config, ImuBias{});
  sim::ImuSample previous = imu.measure(trajectory, kStart + Duration::from_seconds(0.5));
  for (int keyframe = 0; keyframe < kKeyframes; ++keyframe) {
    const Timestamp time = kStart + Duration::from_seconds(0.5 + 0.5 * keyframe);
    const sim::TrajectorySample sample = trajectory.sample(time);
    truth.push_back(sample);
    values.insert(X(keyframe), SE3(sample.T_world_body.rotation() * SO3::exp(noise(0.06)), sample.T_world_body.translation() + noise(0.3)));
    values.insert(V(keyframe), Eigen::Vector3d(sample.velocity_world + noise(0.3)));
    values.insert(B(keyframe), ImuBias{});
    graph.emplace<GpsFactor>(X(keyframe), Eigen::Vector3d(sample.T_world_body * lever_arm + noise(0.3)), lever_arm, gps_noise);
    if (keyframe == 0) continue;
    for (int k = 0; k < kSamplesPerKeyframe; ++k) {
      const sim::ImuSample next = imu.measure(trajectory, previous.message.timestamp + Duration::from_seconds(config.sample_interval));
      ASSERT_TRUE(preintegration.integrate(previous.message.linear_acceleration, previous.message.angular_velocity,
                                           (next.message.timestamp - previous.message.timestamp).seconds())
                      .ok());
      previous = next;
    }
    graph.add(ImuFactor::create(X(keyframe - 1), V(keyframe - 1), X(keyframe), V(keyframe), B(keyframe - 1), preintegration).value());
    graph.add(ImuBiasRandomWalkFactor::create(B(keyframe - 1), B(keyframe), 0.5, 1e-3, 1e-4).value());
    preintegration = ImuPreintegration(config, ImuBias{});
  }
  graph.emplace<PriorFactorSE3>(X(0), values.at<SE3>(X(0)).value(),
                                GaussianNoise::from_sigmas((Eigen::VectorXd(6) << 1.0, 1.0, 1.0, 0.2, 0.2, 0.2).finished()).value());
  graph.emplace<PriorFactorImuBias>(B(0), ImuBias{},
                                    GaussianNoise::from_sigmas((Eigen::VectorXd(6) << 0.5, 0.5, 0.5, 0.05, 0.05, 0.05).finished()).value());

  BatchOptimizerConfig optimizer;
  optimizer.max_iterations = 100;
  const OptimizationSummary summary = optimize(graph, values, optimizer).value();
  EXPECT_LT(summary.final_chi2, summary.initial_chi2);
  // Errors against the truth, and against the solution's own marginal covariances: the
  // estimator is consistent (every rotation error within 4 sigma), with yaw the weakest.
  std::vector<Key> pose_keys;
  for (int keyframe = 0; keyframe < kKeyframes; ++keyframe) pose_keys.push_back(X(keyframe));
  const std::vector<Eigen::MatrixXd> covariances = marginal_covariances(graph, values, pose_keys).value();
  double squared_position_error = 0.0, max_angle = 0.0, max_normalized = 0.0;
  for (int keyframe = 0; keyframe < kKeyframes; ++keyframe) {
    const SE3 estimate = values.at<SE3>(X(keyframe)).value();
    squared_position_error += (estimate.translation() - truth[keyframe].T_world_body.translation()).squaredNorm();
    const Eigen::Vector3d rotation_error = (estimate.rotation().inverse() * truth[keyframe].T_world_body.rotation()).log();
    max_angle = std::max(max_angle, rotation_error.norm());
    for (int axis = 0; axis < 3; ++axis) {
      max_normalized = std::max(max_normalized, std::abs(rotation_error(axis)) / std::sqrt(covariances[keyframe](3 + axis, 3 + axis)));
    }
  }
  const double position_rmse = std::sqrt(squared_position_error / kKeyframes);
  EXPECT_LT(position_rmse, 0.2);  // a GPS fix alone: 0.3 * sqrt(3) = 0.52 m
  EXPECT_LT(max_angle, 0.04);
  EXPECT_LT(max_normalized, 4.0);
  const ImuBias bias = values.at<ImuBias>(B(kKeyframes / 2)).value();
  EXPECT_LT((bias.accelerometer - imu_config.initial_accel_bias).norm(), 0.06);  // from 0.157 at the start
  EXPECT_LT((bias.gyroscope - imu_config.initial_gyro_bias).norm(), 0.002);      // from 0.0123
  RecordProperty("position_rmse_m", std::to_string(position_rmse));
  std::printf("GPS+IMU: position RMSE %.3f m, max angle %.4f rad (%.1f sigma), accel bias error %.4f, gyro bias error %.5f, %d iterations\n",
              position_rmse, max_angle, max_normalized, (bias.accelerometer - imu_config.initial_accel_bias).norm(),
              (bias.gyroscope - imu_config.initial_gyro_bias).norm(), summary.iterations);
}

}  // namespace
}  // namespace hanzo::fusion::graph

namespace hanzo::fusion::graph {
namespace {

TEST(BodyVelocityFactor, ZeroAtTheSensorsVelocityDifferentiatedFromItsTrajectory) {
  const sim::SplineTrajectory trajectory = wavy_trajectory();
  const SE3 T_body_radar(SO3::exp(Eigen::Vector3d(0.1, -0.3, 0.5)), Eigen::Vector3d(3.6, 0.2, 0.5));
  const auto sensor_position = [&](double seconds) {
    return (trajectory.sample(kStart + Duration::from_seconds(seconds)).T_world_body * T_body_radar).translation();
  };
  for (const double t : {1.0, 2.3, 4.1}) {
    const double h = 1e-4;
    const sim::TrajectorySample sample = trajectory.sample(kStart + Duration::from_seconds(t));
    const Eigen::Vector3d velocity_sensor =
        (sample.T_world_body * T_body_radar).rotation().inverse() * ((sensor_position(t + h) - sensor_position(t - h)) / (2.0 * h));
    const BodyVelocityFactor factor(X(0), V(0), velocity_sensor, T_body_radar, sample.angular_velocity_body,
                                    GaussianNoise::from_sigmas(Eigen::Vector3d::Constant(0.01)).value());
    Values values;
    values.insert(X(0), sample.T_world_body);
    values.insert(V(0), sample.velocity_world);
    EXPECT_LT(factor.evaluate(values, nullptr).value().norm(), 1e-3) << "t " << t;  // whitened: < 1e-5 m/s
  }
}

}  // namespace
}  // namespace hanzo::fusion::graph
