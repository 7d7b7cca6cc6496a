// The simulator's trajectory and IMU: spline derivatives against finite differences, noiseless
// IMU samples integrating back to the trajectory, and the noise model's statistics.

#include <cmath>

#include <gtest/gtest.h>

#include "hanzo/fusion/sim/imu_simulator.hpp"
#include "hanzo/fusion/sim/spline_trajectory.hpp"

namespace hanzo::fusion::sim {
namespace {

const Timestamp kStart = Timestamp::from_nanoseconds(1'700'000'000'000'000'000);

// An aggressive 6-DOF path: control poses on a wavy loop with rolling, pitching, turning.
SplineTrajectory wavy_trajectory(int control_points = 24) {
  std::vector<SE3> poses;
  for (int i = 0; i < control_points; ++i) {
    const double a = 0.35 * i;
    poses.emplace_back(SO3::exp({0.3 * std::sin(a), 0.2 * std::cos(1.3 * a), a}),
                       Eigen::Vector3d(5.0 * std::cos(a), 5.0 * std::sin(a), 1.0 + 0.5 * std::sin(2.0 * a)));
  }
  return *SplineTrajectory::create(kStart, Duration::from_milliseconds(500), poses);
}

TEST(SplineTrajectory, DerivativesMatchFiniteDifferences) {
  const SplineTrajectory trajectory = wavy_trajectory();
  const Duration h = Duration::from_microseconds(10);
  for (double t = 0.3; t < 10.0; t += 0.77) {
    const Timestamp time = kStart + Duration::from_seconds(t);
    const TrajectorySample sample = trajectory.sample(time);
    const TrajectorySample before = trajectory.sample(time - h), after = trajectory.sample(time + h);
    const Eigen::Vector3d velocity =
        (after.T_world_body.translation() - before.T_world_body.translation()) / (2.0 * h.seconds());
    EXPECT_LT((velocity - sample.velocity_world).norm(), 1e-6) << t;
    const Eigen::Vector3d acceleration = (after.velocity_world - before.velocity_world) / (2.0 * h.seconds());
    EXPECT_LT((acceleration - sample.acceleration_world).norm(), 1e-5) << t;
    const Eigen::Vector3d omega =
        (before.T_world_body.rotation().inverse() * after.T_world_body.rotation()).log() / (2.0 * h.seconds());
    EXPECT_LT((omega - sample.angular_velocity_body).norm(), 1e-6) << t;
  }
}

TEST(SplineTrajectory, RejectsTooFewControlPoses) {
  EXPECT_FALSE(SplineTrajectory::create(kStart, Duration::from_seconds(1.0), {SE3(), SE3(), SE3()}).ok());
  EXPECT_FALSE(SplineTrajectory::create(kStart, Duration::from_seconds(0.0), {SE3(), SE3(), SE3(), SE3()}).ok());
}

// Strapdown integration of noiseless samples (IMU offset and rotated on the body) reproduces
// the trajectory: the truth is consistent.
TEST(ImuSimulator, NoiselessSamplesIntegrateBackToTheTrajectory) {
  const SplineTrajectory trajectory = wavy_trajectory();
  ImuSimulatorConfig config;
  config.rate_hz = 1000.0;
  config.process_noise_accel = config.process_noise_gyro = 0.0;
  config.accel_bias_random_walk = config.gyro_bias_random_walk = 0.0;
  config.T_body_imu = SE3(SO3::exp({0.1, -0.2, 0.3}), {0.2, -0.1, 0.05});
  const std::vector<ImuSample> samples = ImuSimulator(config).simulate(trajectory);
  ASSERT_EQ(samples.size(), 10501u);  // 10.5 s at 1 kHz, both ends

  const TrajectorySample first = trajectory.sample(kStart);
  SE3 T_world_imu = first.T_world_body * config.T_body_imu;
  // Velocity of the IMU point: v_body + R omega x r.
  Eigen::Vector3d velocity =
      first.velocity_world + first.T_world_body.rotation() * first.angular_velocity_body.cross(config.T_body_imu.translation());
  const Eigen::Vector3d gravity(0.0, 0.0, -config.gravity);
  double worst_position = 0.0, worst_angle = 0.0;
  for (std::size_t k = 0; k + 1 < samples.size(); ++k) {
    const double dt = (samples[k + 1].message.timestamp - samples[k].message.timestamp).seconds();
    // Midpoint rule on the two samples of the step.
    const Eigen::Vector3d omega = 0.5 * (samples[k].message.angular_velocity + samples[k + 1].message.angular_velocity);
    const SO3 R_next = T_world_imu.rotation() * SO3::exp(omega * dt);
    const Eigen::Vector3d a0 = T_world_imu.rotation() * samples[k].message.linear_acceleration + gravity;
    const Eigen::Vector3d a1 = R_next * samples[k + 1].message.linear_acceleration + gravity;
    T_world_imu.translation() += velocity * dt + (2.0 * a0 + a1) / 6.0 * dt * dt;
    velocity += 0.5 * (a0 + a1) * dt;
    T_world_imu.rotation() = R_next;
    const SE3 truth = trajectory.sample(samples[k + 1].message.timestamp).T_world_body * config.T_body_imu;
    worst_position = std::max(worst_position, (truth.translation() - T_world_imu.translation()).norm());
    worst_angle = std::max(worst_angle, (truth.rotation().inverse() * T_world_imu.rotation()).angle());
  }
  // 10.5 s of dead reckoning on a 6-DOF path with up to ~4 m/s^2 and ~1.5 rad/s.
  EXPECT_LT(worst_position, 0.01);
  EXPECT_LT(worst_angle, 1e-4);
}

TEST(ImuSimulator, NoiseAndBiasWalkFollowTheConfiguredDensities) {
  // At rest and level: the mean reading is gravity up, the spread the configured noise.
  const SplineTrajectory still = *SplineTrajectory::create(kStart, Duration::from_seconds(10.0), {SE3(), SE3(), SE3(), SE3(), SE3()});
  ImuSimulatorConfig config;
  config.rate_hz = 500.0;
  config.accel_bias_random_walk = config.gyro_bias_random_walk = 0.0;
  config.initial_accel_bias = {0.05, -0.02, 0.01};
  const std::vector<ImuSample> samples = ImuSimulator(config).simulate(still);
  ASSERT_EQ(samples.size(), 10001u);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const ImuSample& s : samples) mean += s.message.linear_acceleration;
  mean /= static_cast<double>(samples.size());
  double variance = 0.0;
  for (const ImuSample& s : samples) variance += (s.message.linear_acceleration - mean).squaredNorm();
  variance /= 3.0 * static_cast<double>(samples.size() - 1);
  EXPECT_LT((mean - Eigen::Vector3d(0.05, -0.02, 9.81 + 0.01)).norm(), 4.0 * 0.1 / std::sqrt(10001.0) * std::sqrt(3.0));
  EXPECT_NEAR(std::sqrt(variance), config.process_noise_accel, 0.03 * config.process_noise_accel);

  // Bias random walk: after T seconds each axis has variance walk^2 T; over 200 seeds.
  ImuSimulatorConfig walking;
  walking.rate_hz = 100.0;
  walking.process_noise_accel = walking.process_noise_gyro = 0.0;
  walking.gyro_bias_random_walk = 0.01;
  double sum_squares = 0.0;
  const int runs = 200;
  for (int seed = 1; seed <= runs; ++seed) {
    walking.seed = static_cast<uint64_t>(seed);
    sum_squares += ImuSimulator(walking).simulate(still).back().gyro_bias.squaredNorm();
  }
  const double per_axis_variance = sum_squares / (3.0 * runs);
  const double expected = 0.01 * 0.01 * 20.0;  // the last sample holds 20 s - 1 step of walk
  EXPECT_NEAR(per_axis_variance, expected, 0.2 * expected);

  // Deterministic per seed.
  EXPECT_EQ(ImuSimulator(config).simulate(still)[77].message.angular_velocity,
            ImuSimulator(config).simulate(still)[77].message.angular_velocity);
}

}  // namespace
}  // namespace hanzo::fusion::sim
