// Map frames (estimate/map_frame.hpp): the map pose model's Jacobians against numerical
// differentiation, and the EKF's anchored update: a map started tilted is levelled by the IMU.

#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/estimate/error_state_ekf.hpp"
#include "hanzo/fusion/estimate/map_frame.hpp"

namespace hanzo::fusion::estimate {
namespace {

Eigen::Vector3d random_vector(std::mt19937& rng, double scale) {
  std::normal_distribution<double> n(0.0, scale);
  return {n(rng), n(rng), n(rng)};
}

TEST(MapFrame, PoseModelJacobiansMatchNumericalDifferentiation) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 20; ++trial) {
    NavigationState state;
    state.position = random_vector(rng, 10.0);
    state.R_world_body = SO3::exp(random_vector(rng, 0.5));
    const SE3 T_body_sensor(SO3::exp(random_vector(rng, 0.3)), random_vector(rng, 0.5));
    const MapFrameAnchor anchor{SE3(SO3::exp(random_vector(rng, 0.5)), random_vector(rng, 10.0)),
                                SE3(SO3::exp(random_vector(rng, 0.3)), random_vector(rng, 2.0))};
    const SE3 measured = SE3(SO3::exp(random_vector(rng, 0.05)), random_vector(rng, 0.1)) *
                         anchor.T_world_map().inverse() * SE3(state.R_world_body, state.position) * T_body_sensor;
    const MapPoseModel model(0, measured, MapPoseModel::Matrix6::Identity(), T_body_sensor);
    MapPoseModel::StateJacobian H_state;
    MapPoseModel::Matrix6 H_anchor;
    model.residual(state, anchor, &H_state, &H_anchor);
    constexpr double h = 1e-6;
    for (int i = 0; i < kErrorStateDimension; ++i) {
      ErrorVector delta = ErrorVector::Zero();
      delta(i) = h;
      const MapPoseModel::Vector6 numeric =
          -(model.residual(state.plus(delta), anchor, nullptr, nullptr) - model.residual(state.plus(-delta), anchor, nullptr, nullptr)) / (2 * h);
      for (int row = 0; row < 6; ++row) EXPECT_NEAR(H_state(row, i), numeric(row), 1e-6) << "state column " << i << " row " << row;
    }
    for (int i = 0; i < 6; ++i) {
      Eigen::Matrix<double, 6, 1> delta = Eigen::Matrix<double, 6, 1>::Zero();
      delta(i) = h;
      const MapPoseModel::Vector6 numeric =
          -(model.residual(state, anchor.plus(delta), nullptr, nullptr) - model.residual(state, anchor.plus(-delta), nullptr, nullptr)) / (2 * h);
      for (int row = 0; row < 6; ++row) EXPECT_NEAR(H_anchor(row, i), numeric(row), 1e-6) << "anchor column " << i << " row " << row;
    }
  }
}

TEST(MapFrame, TheEkfAnchorsFramesAtTheEstimateAndMovesThemWithTheWorld) {
  ErrorStateEkf filter(FilterConfig{});
  NavigationState state;
  state.position = Eigen::Vector3d(3, -2, 1);
  state.R_world_body = SO3::exp(Eigen::Vector3d(0.02, -0.01, 0.7));
  ErrorCovariance P = ErrorCovariance::Identity() * 1e-4;
  P.block<3, 3>(kPositionIndex, kPositionIndex) = Eigen::Matrix3d::Identity();  // 1 m
  filter.reset(state, P);
  const SE3 T_body_sensor(SO3::exp(Eigen::Vector3d(0, 0, 0.1)), Eigen::Vector3d(0.5, 0, 1.2));
  const SE3 T_map_sensor(SO3::exp(Eigen::Vector3d(0, 0.1, 0)), Eigen::Vector3d(1, 2, 0));
  const std::optional<int> frame = filter.add_map_frame(T_body_sensor * T_map_sensor.inverse());
  ASSERT_EQ(frame, 0);
  EXPECT_FALSE(filter.map_frame(1));
  const SE3 expected = SE3(state.R_world_body, state.position) * T_body_sensor * T_map_sensor.inverse();
  EXPECT_TRUE(filter.map_frame(0)->matrix().isApprox(expected.matrix(), 1e-12));
  // The same map pose again: no information about the state (the frame's error is the pose's),
  // so nothing moves and the innovation's covariance is the measurement's alone.
  const MapPoseModel::Matrix6 R = MapPoseModel::Matrix6::Identity() * 1e-4;
  const UpdateOutcome outcome = filter.update_map_pose(MapPoseModel(0, T_map_sensor, R, T_body_sensor));
  EXPECT_EQ(outcome.status, UpdateStatus::kApplied);
  EXPECT_NEAR(outcome.mahalanobis_squared, 0.0, 1e-12);
  EXPECT_TRUE(filter.state().position.isApprox(state.position, 1e-9));
  EXPECT_NEAR(filter.covariance()(kPositionIndex, kPositionIndex), 1.0, 1e-6);  // a 1 m prior stays 1 m
  // Nothing about the frame's own pose was measured: it stays where it was anchored.
  EXPECT_TRUE(filter.map_frame(0)->matrix().isApprox(expected.matrix(), 1e-9));
  // A world correction moves the frame with the estimate.
  const SE3 correction(SO3::exp(Eigen::Vector3d(0, 0, 0.3)), Eigen::Vector3d(1, 2, 3));
  const SE3 before = *filter.map_frame(0);
  filter.apply_world_transform(correction);
  EXPECT_TRUE(filter.map_frame(0)->matrix().isApprox((correction * before).matrix(), 1e-12));
  // Map poses are unknown to frames that do not exist; reset() removes them.
  EXPECT_EQ(filter.update_map_pose(MapPoseModel(1, T_map_sensor, R, T_body_sensor)).status, UpdateStatus::kNumericalFailure);
  filter.reset(state, P);
  EXPECT_FALSE(filter.map_frame(0));
}

}  // namespace
}  // namespace hanzo::fusion::estimate
