// ErrorStateEkf: convergence on a static body, chi-square gating of a 50 m GNSS jump (the
// estimate does not move), the IMU spike filter.

#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/estimate/error_state_ekf.hpp"
#include "hanzo/fusion/estimate/imu_spike_filter.hpp"
#include "hanzo/fusion/estimate/position_models.hpp"

namespace hanzo::fusion::estimate {
namespace {

ErrorCovariance initial_covariance() {
  ErrorVector sigmas;
  sigmas << 5, 5, 5, 0.01, 0.01, 0.01, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05, 0.001, 0.001, 0.001, 1e-6, 1e-6, 0.01;
  return sigmas.array().square().matrix().asDiagonal();
}

TEST(ErrorStateEkf, ConvergesOnGnssAndRejectsA50MeterJumpWithoutMoving) {
  FilterConfig config;
  config.imu_noise.sample_interval = 0.01;
  ErrorStateEkf ekf(config);
  ekf.reset(NavigationState{}, initial_covariance());
  const ImuSample still{Timestamp::from_nanoseconds(1), Eigen::Vector3d::Zero(), Eigen::Vector3d(0, 0, kStandardGravity)};
  const Eigen::Vector3d truth(3.0, -2.0, 1.0);
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 1.0);
  for (int second = 0; second < 60; ++second) {
    for (int k = 0; k < 100; ++k) ekf.predict(still, 0.01);
    const Eigen::Vector3d fix = truth + Eigen::Vector3d(noise(rng), noise(rng), noise(rng));
    const UpdateOutcome outcome = ekf.update(GnssPositionModel(fix, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero()));
    EXPECT_NE(outcome.status, UpdateStatus::kNumericalFailure);
  }
  // Steady state of a random-walk velocity observed by 1 m fixes: sigma about 0.6 m per axis.
  const double sigma = std::sqrt(ekf.covariance().block<3, 3>(0, 0).trace());
  EXPECT_LT(sigma, 1.5);
  EXPECT_LT((ekf.state().position - truth).norm(), 3.0 * sigma);

  const NavigationState before = ekf.state();
  const ErrorCovariance covariance_before = ekf.covariance();
  const UpdateOutcome jump =
      ekf.update(GnssPositionModel(truth + Eigen::Vector3d(50.0, 0.0, 0.0), Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero()));
  EXPECT_EQ(jump.status, UpdateStatus::kRejectedByGate);
  EXPECT_GT(jump.mahalanobis_squared, jump.gate);
  EXPECT_EQ(ekf.state().position, before.position);
  EXPECT_EQ(ekf.covariance(), covariance_before);
}

TEST(ErrorStateEkf, GateProbabilityOneAcceptsEverything) {
  FilterConfig config;
  config.gate_probability = 1.0;
  ErrorStateEkf ekf(config);
  ekf.reset(NavigationState{}, initial_covariance() * 1e-4);
  const UpdateOutcome outcome =
      ekf.update(GnssPositionModel(Eigen::Vector3d(50.0, 0.0, 0.0), Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero()));
  EXPECT_EQ(outcome.status, UpdateStatus::kApplied);
  EXPECT_GT(ekf.state().position.x(), 0.0);
}

TEST(ImuSpikeFilter, RejectsASpikeAndAcceptsAPersistentChange) {
  ImuNoise noise;
  noise.process_noise_accel = 0.1;
  ImuSpikeFilter filter({}, noise);
  const auto sample = [](int k, double ax) {
    return ImuSample{Timestamp::from_nanoseconds(1'000'000'000 + k * 5'000'000), Eigen::Vector3d::Zero(), Eigen::Vector3d(ax, 0, 9.8)};
  };
  EXPECT_TRUE(filter.accept(sample(0, 0.0)));
  EXPECT_TRUE(filter.accept(sample(1, 0.5)));
  EXPECT_FALSE(filter.accept(sample(2, 60.0)));  // spike
  EXPECT_TRUE(filter.accept(sample(3, 0.6)));
  int accepted_at = -1;
  for (int k = 4; k < 20 && accepted_at < 0; ++k) {
    if (filter.accept(sample(k, 40.0))) accepted_at = k;  // a real, lasting change (an impact)
  }
  // Accepted once the jerk limit over the time since the reference allows it, and at the latest
  // after max_consecutive = 5 rejections.
  EXPECT_GT(accepted_at, 4);
  EXPECT_LE(accepted_at, 9);
}

}  // namespace
}  // namespace hanzo::fusion::estimate
