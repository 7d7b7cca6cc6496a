// ErrorStateEkf: convergence on a static body, chi-square gating of a 50 m GNSS jump (the
// estimate does not move), the pose clone against the augmented-state filter; the IMU spike
// filter; the UKF's analytic propagation of its linear sigma points.

#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/estimate/error_state_ekf.hpp"
#include "hanzo/fusion/estimate/imu_spike_filter.hpp"
#include "hanzo/fusion/estimate/position_models.hpp"
#include "hanzo/fusion/estimate/unscented_kalman_filter.hpp"

namespace hanzo::fusion::estimate {
namespace {

ErrorCovariance initial_covariance() {
  ErrorVector sigmas;
  sigmas << 5, 5, 5, 0.01, 0.01, 0.01, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05, 0.001, 0.001, 0.001, 1e-6, 1e-6, 0.01, 0.03, 0.01, 0.005;
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


// The EKF's clone bookkeeping against an explicit augmented-state EKF (the error state + 6 cloned pose
// errors) run densely on the same predictions and updates.
TEST(ErrorStateEkf, PoseCloneMatchesTheAugmentedStateFilter) {
  using Augmented = Eigen::Matrix<double, kErrorStateDimension + 6, kErrorStateDimension + 6>;
  FilterConfig config;
  config.imu_noise.sample_interval = 0.01;
  config.gate_probability = 1.0;
  ErrorStateEkf ekf(config);
  ekf.reset(NavigationState{}, initial_covariance());
  const ImuSample turning{Timestamp::from_nanoseconds(1), Eigen::Vector3d(0.0, 0.05, 0.3), Eigen::Vector3d(0.5, 0.2, 9.8)};
  for (int k = 0; k < 20; ++k) ekf.predict(turning, 0.01);
  ekf.clone_pose();
  Augmented P = Augmented::Zero();
  P.topLeftCorner<kErrorStateDimension, kErrorStateDimension>() = ekf.covariance();
  P.topRightCorner<kErrorStateDimension, 6>() = ekf.covariance().leftCols<6>();
  P.bottomLeftCorner<6, kErrorStateDimension>() = ekf.covariance().topRows<6>();
  P.bottomRightCorner<6, 6>() = ekf.covariance().topLeftCorner<6, 6>();
  Eigen::Matrix<double, kErrorStateDimension + 6, 1> clone_delta = Eigen::Matrix<double, kErrorStateDimension + 6, 1>::Zero();
  for (int step = 0; step < 5; ++step) {
    for (int k = 0; k < 10; ++k) {
      ImuTransition transition;
      const NavigationState before = ekf.state();
      propagate_state(before, body_motion(before, turning, config.imu_mounting), 0.01, config.imu_mounting, &transition);
      Augmented phi = Augmented::Identity();
      phi.topLeftCorner<kErrorStateDimension, kErrorStateDimension>() = transition_matrix(transition);
      Augmented q = Augmented::Zero();
      q.topLeftCorner<kErrorStateDimension, kErrorStateDimension>() = process_noise(config.imu_noise, 0.01);
      P = phi * P * phi.transpose() + q;
      ekf.predict(turning, 0.01);
    }
    const GnssPositionModel model(Eigen::Vector3d(0.3 * step, -0.2, 0.1), Eigen::Matrix3d::Identity() * 0.5, Eigen::Vector3d(0, 0, 1));
    MeasurementJacobian H;
    const MeasurementVector r = model.residual(ekf.state(), &H);
    Eigen::Matrix<double, 3, kErrorStateDimension + 6> H_augmented = Eigen::Matrix<double, 3, kErrorStateDimension + 6>::Zero();
    H_augmented.leftCols<kErrorStateDimension>() = H;
    const Eigen::Matrix3d S = H_augmented * P * H_augmented.transpose() + model.covariance();
    const Eigen::Matrix<double, kErrorStateDimension + 6, 3> K = P * H_augmented.transpose() * S.inverse();
    const Eigen::Matrix<double, kErrorStateDimension + 6, 1> delta = K * r;
    clone_delta.tail<6>() += delta.tail<6>();
    P -= K * S * K.transpose();
    Augmented G = Augmented::Identity();
    G.block<3, 3>(kOrientationIndex, kOrientationIndex) -= SO3::hat(0.5 * delta.segment<3>(kOrientationIndex));
    P = G * P * G.transpose();
    ASSERT_EQ(ekf.update(model).status, UpdateStatus::kApplied);
  }
  const std::optional<PoseClone> clone = ekf.pose_clone();
  ASSERT_TRUE(clone.has_value());
  EXPECT_LT((clone->cross - P.bottomLeftCorner<6, kErrorStateDimension>()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((clone->covariance - P.bottomRightCorner<6, 6>()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((clone->correction - clone_delta.tail<6>()).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((ekf.covariance() - P.topLeftCorner<kErrorStateDimension, kErrorStateDimension>()).cwiseAbs().maxCoeff(), 1e-9);
}


// The UKF propagates the sigma points of the linear dimensions (position, velocity, gravity)
// analytically; the result must equal pushing all 43 sigma points through propagate_state().
TEST(UnscentedKalmanFilter, PredictEqualsFullSigmaPointPropagation) {
  FilterConfig config;
  config.imu_mounting = {SO3::exp(Eigen::Vector3d(0.02, -0.01, 0.3)), Eigen::Vector3d(0.1, 0.05, 0.0)};
  const UkfConfig ukf_config{0.5, 2.0, 0.0};
  UnscentedKalmanFilter ukf(config, ukf_config);
  NavigationState state;
  state.velocity = Eigen::Vector3d(3.0, 1.0, 0.0);
  state.R_world_body = SO3::exp(Eigen::Vector3d(0.1, -0.05, 1.2));
  Eigen::Matrix<double, kErrorStateDimension, kErrorStateDimension> A = Eigen::Matrix<double, kErrorStateDimension, kErrorStateDimension>::Random() * 0.05;
  const ErrorCovariance P = A * A.transpose() + initial_covariance();
  ukf.reset(state, P);
  const ImuSample sample{Timestamp::from_nanoseconds(1), Eigen::Vector3d(0.2, -0.1, 0.6), Eigen::Vector3d(1.0, 0.5, 9.7)};
  const double dt = 0.01;
  ukf.predict(sample, dt);

  // Reference: the same sigma points (permuted Cholesky), all propagated.
  constexpr std::array<int, kErrorStateDimension> order{3, 4, 5, 9, 10, 11, 12, 13, 14, 19, 0, 1, 2, 6, 7, 8, 15, 16, 17, 18, 20};
  const double n = kErrorStateDimension;
  const double lambda = ukf_config.alpha * ukf_config.alpha * (n + ukf_config.kappa) - n;
  ErrorCovariance permuted;
  for (int i = 0; i < kErrorStateDimension; ++i) {
    for (int j = 0; j < kErrorStateDimension; ++j) permuted(i, j) = P(order[static_cast<size_t>(i)], order[static_cast<size_t>(j)]);
  }
  const ErrorCovariance root = Eigen::LLT<ErrorCovariance>((n + lambda) * (permuted + 1e-15 * ErrorCovariance::Identity())).matrixL();
  const auto propagate = [&](const NavigationState& x) {
    return propagate_state(x, body_motion(x, sample, config.imu_mounting), dt, config.imu_mounting, nullptr);
  };
  const NavigationState center = propagate(state);
  std::vector<ErrorVector> deltas{ErrorVector::Zero()};
  for (int sign : {1, -1}) {
    for (int column = 0; column < kErrorStateDimension; ++column) {
      ErrorVector o;
      for (int i = 0; i < kErrorStateDimension; ++i) o(order[static_cast<size_t>(i)]) = sign * root(i, column);
      deltas.push_back(propagate(state.plus(o)).minus(center));
    }
  }
  const double w = 1.0 / (2.0 * (n + lambda));
  const double wc0 = lambda / (n + lambda) + (1.0 - ukf_config.alpha * ukf_config.alpha + ukf_config.beta);
  ErrorVector mean = ErrorVector::Zero();
  for (size_t i = 1; i < deltas.size(); ++i) mean += w * deltas[i];
  ErrorCovariance expected = wc0 * mean * mean.transpose();
  for (size_t i = 1; i < deltas.size(); ++i) expected += w * (deltas[i] - mean) * (deltas[i] - mean).transpose();
  expected += process_noise(config.imu_noise, dt);
  EXPECT_LT((ukf.covariance() - expected).cwiseAbs().maxCoeff(), 1e-10);
  EXPECT_LT(ukf.state().minus(center.plus(mean)).norm(), 1e-10);
}

}  // namespace
}  // namespace hanzo::fusion::estimate
