// Every measurement model's Jacobian and the IMU transition against numerical differentiation;
// the block-sparse covariance propagation against the dense product; chi-square quantiles.

#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/estimate/attitude_models.hpp"
#include "hanzo/fusion/estimate/chi_square.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"
#include "hanzo/fusion/estimate/position_models.hpp"
#include "hanzo/fusion/estimate/range_models.hpp"
#include "hanzo/fusion/estimate/static_alignment.hpp"
#include "hanzo/fusion/estimate/velocity_models.hpp"

namespace hanzo::fusion::estimate {
namespace {

NavigationState random_state(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  const auto v = [&] { return Eigen::Vector3d(n(rng), n(rng), n(rng)); };
  NavigationState state;
  state.position = 10.0 * v();
  state.R_world_body = SO3::exp(0.5 * v());  // tilts up to ~30 degrees, away from gimbal lock
  state.velocity = 2.0 * v();
  state.accel_bias = 0.1 * v();
  state.gyro_bias = 0.01 * v();
  state.gravity = Eigen::Vector3d(0.01, -0.02, -9.8) + 0.01 * v();
  state.wheel_speed_scale = 1.0 + 0.02 * n(rng);
  state.gyro_yaw_scale = 1.0 + 0.02 * n(rng);
  state.wheel_heading_drift = 0.01 * n(rng);
  return state;
}

// Central differences of residual(x (+) e_i * h); H = -d residual / d dx.
void expect_jacobian_matches(const MeasurementModel& model, const NavigationState& state, double tolerance) {
  MeasurementJacobian analytic;
  model.residual(state, &analytic);
  ASSERT_EQ(analytic.rows(), model.dimension());
  constexpr double h = 1e-6;
  for (int i = 0; i < kErrorStateDimension; ++i) {
    ErrorVector delta = ErrorVector::Zero();
    delta(i) = h;
    const MeasurementVector plus = model.residual(state.plus(delta), nullptr);
    const MeasurementVector minus = model.residual(state.plus(-delta), nullptr);
    const MeasurementVector numeric = -(plus - minus) / (2.0 * h);
    for (int row = 0; row < model.dimension(); ++row) {
      EXPECT_NEAR(analytic(row, i), numeric(row), tolerance) << model.name() << " row " << row << " column " << i;
    }
  }
}

TEST(MeasurementModels, JacobiansMatchNumericalDifferentiation) {
  std::mt19937 rng(7);
  const SE3 T_body_sensor(SO3::exp(Eigen::Vector3d(0.1, -0.2, 0.3)), Eigen::Vector3d(0.4, -0.1, 0.6));
  const GyroReading gyro{Eigen::Vector3d(0.3, -0.2, 0.5), SO3::exp(Eigen::Vector3d(0.05, 0.02, -0.1))};
  for (int trial = 0; trial < 20; ++trial) {
    const NavigationState state = random_state(rng);
    expect_jacobian_matches(GnssPositionModel(Eigen::Vector3d(1, 2, 3), Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.2, 0.1, 1.0)),
                            state, 1e-6);
    expect_jacobian_matches(PoseModel(SE3::exp((SE3::Tangent() << 1, 2, 3, 0.2, -0.1, 0.3).finished()),
                                      Eigen::Matrix<double, 6, 6>::Identity(), T_body_sensor),
                            state, 1e-6);
    expect_jacobian_matches(SensorVelocityModel(Eigen::Vector3d(1, 0, 0), Eigen::Matrix3d::Identity(), T_body_sensor, gyro), state, 1e-6);
    WheelOdometryMeasurement wheels;
    wheels.forward_speed = 1.2;
    wheels.yaw_rate = 0.1;
    expect_jacobian_matches(WheelOdometryModel(wheels, T_body_sensor, gyro), state, 1e-6);
    wheels.vertical_constraint = false;
    wheels.use_yaw_rate = false;
    expect_jacobian_matches(WheelOdometryModel(wheels, T_body_sensor, gyro), state, 1e-6);
    expect_jacobian_matches(ZeroVelocityModel(0.01, 0.01, true, gyro), state, 1e-6);
    const ImuAttitudeModel attitude(SO3::exp(Eigen::Vector3d(0.1, 0.2, 2.0)), Eigen::Matrix3d::Identity() * 1e-4, gyro.R_body_imu,
                                    {true, true, true});
    ASSERT_TRUE(attitude.usable());
    expect_jacobian_matches(attitude, state, 1e-5);
    expect_jacobian_matches(ImuAttitudeModel(SO3(), Eigen::Matrix3d::Identity(), SO3(), {false, true, true}), state, 1e-5);
    expect_jacobian_matches(GravityMagnitudeModel(9.81, 0.01), state, 1e-6);
    expect_jacobian_matches(PlanarMotionModel(0.5, 0.01, 0.01), state, 1e-6);
    // A rangefinder looking down (its +x axis turned to the body's -z), 1.5 m above the floor.
    const SE3 T_body_down(SO3::exp(Eigen::Vector3d(0.05, M_PI / 2.0, -0.1)), Eigen::Vector3d(0.1, -0.2, -0.05));
    for (const double half_field_of_view : {0.0, 0.13, 0.4}) {
      expect_jacobian_matches(FloorRangeModel(1.4, 1e-4, state.position.z() - 1.5, T_body_down, half_field_of_view, true), state, 1e-6);
    }
  }
}

// Level, 1.2 m above the floor, the beam straight down from 0.1 m below the body: it reads 1.1 m;
// tilted 30 degrees about x, a thin beam reads the slant 1.1 / cos 30 degrees, a 20 degree cone
// its ray nearest to straight down (20 degrees off).
TEST(MeasurementModels, FloorRangeIsTheConesDistanceToTheFloorPlane) {
  NavigationState state;
  state.position = Eigen::Vector3d(3.0, -2.0, 1.2);
  const SE3 T_body_down(SO3::exp(Eigen::Vector3d(0.0, M_PI / 2.0, 0.0)), Eigen::Vector3d(0.0, 0.0, -0.1));
  const FloorRangeModel thin(1.0, 1e-4, 0.0, T_body_down, 0.0);
  const FloorRangeModel cone(1.0, 1e-4, 0.0, T_body_down, 10.0 * M_PI / 180.0);
  EXPECT_NEAR(thin.residual(state, nullptr)(0), 1.0 - 1.1, 1e-12);
  EXPECT_NEAR(cone.residual(state, nullptr)(0), 1.0 - 1.1, 1e-12);
  state.R_world_body = rotation_from_roll_pitch_yaw(M_PI / 6.0, 0.0, 0.7);
  const double sensor_height = 1.2 - 0.1 * std::cos(M_PI / 6.0);
  EXPECT_NEAR(thin.residual(state, nullptr)(0), 1.0 - sensor_height / std::cos(M_PI / 6.0), 1e-12);
  EXPECT_NEAR(cone.residual(state, nullptr)(0), 1.0 - sensor_height / std::cos(M_PI / 9.0), 1e-12);
}

TEST(MeasurementModels, AttitudeResidualWrapsAroundPi) {
  NavigationState state;
  state.R_world_body = rotation_from_roll_pitch_yaw(0.0, 0.0, 3.1);
  const ImuAttitudeModel model(rotation_from_roll_pitch_yaw(0.0, 0.0, -3.1), Eigen::Matrix3d::Identity(), SO3(), {false, false, true});
  EXPECT_NEAR(model.residual(state, nullptr)(0), 2.0 * M_PI - 6.2, 1e-9);
  const ImuAttitudeModel gimbal(rotation_from_roll_pitch_yaw(0.0, 1.56, 0.0), Eigen::Matrix3d::Identity(), SO3(), {true, true, true});
  EXPECT_FALSE(gimbal.usable());
}

TEST(ImuPropagation, TransitionMatchesNumericalDifferentiation) {
  std::mt19937 rng(3);
  const ImuMounting mounting{SO3::exp(Eigen::Vector3d(0.02, -0.03, 0.5)), Eigen::Vector3d::Zero()};
  const ImuSample sample{Timestamp::from_nanoseconds(1), Eigen::Vector3d(0.4, -0.3, 0.8), Eigen::Vector3d(1.0, -0.5, 9.9)};
  const double dt = 0.01;
  for (int trial = 0; trial < 10; ++trial) {
    const NavigationState state = random_state(rng);
    ImuTransition transition;
    const NavigationState next = propagate_state(state, body_motion(state, sample, mounting), dt, mounting, &transition);
    const ErrorCovariance phi = transition_matrix(transition);
    constexpr double h = 1e-6;
    for (int i = 0; i < kErrorStateDimension; ++i) {
      ErrorVector delta = ErrorVector::Zero();
      delta(i) = h;
      const auto step = [&](const NavigationState& s) { return propagate_state(s, body_motion(s, sample, mounting), dt, mounting, nullptr); };
      const ErrorVector numeric = (step(state.plus(delta)).minus(next) - step(state.plus(-delta)).minus(next)) / (2.0 * h);
      // First-order discretization: Phi agrees with the exact step up to O(dt^2) terms.
      for (int row = 0; row < kErrorStateDimension; ++row) EXPECT_NEAR(phi(row, i), numeric(row), 2e-3) << row << "," << i;
    }
  }
}

TEST(ImuPropagation, SparseCovariancePropagationEqualsDenseProduct) {
  std::mt19937 rng(5);
  const ImuMounting mounting{SO3::exp(Eigen::Vector3d(0.1, 0.0, -0.2)), Eigen::Vector3d(0.1, 0.0, 0.05)};
  const ImuNoise noise{0.2, 0.02, 0.003, 0.0004, 0.005, 1e-4, 2e-5, 3e-5};
  const NavigationState state = random_state(rng);
  ImuTransition transition;
  propagate_state(state, body_motion(state, {{}, Eigen::Vector3d(0.2, 0.1, -0.3), Eigen::Vector3d(0.5, 0.2, 9.7)}, mounting), 0.005,
                  mounting, &transition);
  Eigen::Matrix<double, kErrorStateDimension, kErrorStateDimension> A = Eigen::Matrix<double, kErrorStateDimension, kErrorStateDimension>::Random();
  ErrorCovariance P = A * A.transpose() + ErrorCovariance::Identity();
  const ErrorCovariance phi = transition_matrix(transition);
  const ErrorCovariance dense = phi * P * phi.transpose() + process_noise(noise, transition.dt);
  propagate_covariance(P, transition, noise);
  EXPECT_LT((P - dense).cwiseAbs().maxCoeff(), 1e-12 * dense.cwiseAbs().maxCoeff());
}

TEST(ChiSquare, QuantilesMatchTables) {
  EXPECT_NEAR(chi_square_quantile(0.95, 1), 3.841459, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.95, 3), 7.814728, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.999, 6), 22.457744, 1e-5);
  EXPECT_NEAR(chi_square_quantile(0.025, 150), 117.9845, 1e-3);  // NEES band: 50 runs x 3 dof
  EXPECT_NEAR(chi_square_cdf(chi_square_quantile(0.3, 4), 4), 0.3, 1e-10);
}

TEST(StaticAlignment, RecoversRollPitchAndGyroBiasAndRefusesMotion) {
  const SO3 truth = rotation_from_roll_pitch_yaw(0.05, -0.08, 0.0);
  const Eigen::Vector3d bias(0.01, -0.02, 0.005);
  std::mt19937 rng(1);
  std::normal_distribution<double> n(0.0, 0.02);
  std::vector<ImuSample> samples;
  for (int i = 0; i < 200; ++i) {
    samples.push_back({Timestamp::from_nanoseconds(1'000'000'000 + i * 5'000'000), bias + Eigen::Vector3d(n(rng), n(rng), n(rng)),
                       truth.inverse() * Eigen::Vector3d(0, 0, 9.81) + Eigen::Vector3d(n(rng), n(rng), n(rng))});
  }
  const Result<StaticAlignment> alignment = align_static(samples, ImuMounting{}, 0.0);
  ASSERT_TRUE(alignment.ok()) << alignment.error().message;
  EXPECT_LT((alignment->R_world_body.inverse() * truth).angle(), 0.003);
  EXPECT_LT((alignment->gyro_bias - bias).norm(), 0.005);
  EXPECT_NEAR(alignment->gravity_magnitude, 9.81, 0.01);
  // Vibration (100 Hz, +-3 m/s^2, zero mean: the body stays put) is not motion.
  std::vector<ImuSample> vibrating = samples;
  for (size_t i = 0; i < vibrating.size(); ++i) vibrating[i].linear_acceleration.x() += i % 2 == 0 ? 3.0 : -3.0;
  const Result<StaticAlignment> vibrated = align_static(vibrating, ImuMounting{}, 0.0);
  ASSERT_TRUE(vibrated.ok()) << vibrated.error().message;
  EXPECT_LT((vibrated->R_world_body.inverse() * truth).angle(), 0.003);
  // A push (1 m/s^2 forward for 0.3 s, then braking) is.
  for (size_t i = 40; i < 100; ++i) samples[i].linear_acceleration.x() += i < 70 ? 1.0 : -1.0;
  const Result<StaticAlignment> moving = align_static(samples, ImuMounting{}, 0.0);
  ASSERT_FALSE(moving.ok());
  EXPECT_NE(moving.error().message.find("moving"), std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion::estimate
