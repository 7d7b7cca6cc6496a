// The backend behind the Frontend: keyframes become pose nodes, loop closures bend the
// trajectory back onto the truth, corrections flow back into the frontend; GNSS fixes attach
// to keyframes; bad input changes nothing.

#include <algorithm>
#include <cmath>
#include <random>

#include <Eigen/Geometry>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/graph/imu_factors.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/pipeline/keyframe_graph.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using ::testing::HasSubstr;

// warehouse_robot with its IMU and wheels only (two laps of the aisles; the left wheel slips
// 25-33 s): the frontend dead-reckons and drifts.
sim::Scenario dead_reckoning_warehouse() {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/warehouse_robot.yaml").value();
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& sensor) {
    return sensor.modality != config::SensorModality::kImu && sensor.modality != config::SensorModality::kWheelOdometry;
  });
  return scenario;
}

// Position RMSE after moving the estimate so that its first pose lies on the truth (without
// GNSS the frontend's world frame starts at an arbitrary heading: drift is what counts).
double position_rmse(const std::vector<std::pair<SE3, SE3>>& estimate_and_truth) {
  const SE3 alignment = estimate_and_truth.front().second * estimate_and_truth.front().first.inverse();
  double squared = 0.0;
  for (const auto& [estimate, truth] : estimate_and_truth) squared += ((alignment * estimate).translation() - truth.translation()).squaredNorm();
  return std::sqrt(squared / static_cast<double>(estimate_and_truth.size()));
}

struct LoopClosureRun {
  int closures = 0;
  int corrections = 0;
  std::vector<Timestamp> loop_batches;  // keyframe times of the loop closures' batches
  size_t keyframes = 0;
  double optimized_rmse = 0.0, dead_reckoned_rmse = 0.0;            // keyframe positions
  double final_with_backend = 0.0, final_dead_reckoned = 0.0;      // the live frontend at the end
};

// Loop closures as a place recognizer would report them on the second lap: for a keyframe
// within 0.8 m of one at least 40 keyframes older, the true relative pose with 2 cm / 0.2 deg
// noise; plus one wrong closure (5 m off) that the DCS kernel must ignore.
LoopClosureRun run_warehouse_loop_closures(double loop_batch_interval_s) {
  const sim::Scenario scenario = dead_reckoning_warehouse();
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  const sim::SplineTrajectory& trajectory = simulation->trajectory();
  auto session = Frontend::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario)).value();
  auto frontend_only = Frontend::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario)).value();
  std::vector<msgs::Keyframe> frontend_only_keyframes;
  frontend_only->set_keyframe_callback([&](const msgs::Keyframe& keyframe) { frontend_only_keyframes.push_back(keyframe); });

  KeyframeGraphConfig config;  // deterministic: a full batch after loop closures, none in the background
  config.smoother.background_batch = false;
  config.batch_on_loop_closure = true;
  config.loop_batch_interval_s = loop_batch_interval_s;
  KeyframeGraph backend(config);
  backend.attach(*session);
  std::mt19937_64 random(4);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::Matrix<double, 6, 6> closure_covariance = Eigen::Matrix<double, 6, 6>::Identity();
  closure_covariance.topLeftCorner<3, 3>() *= 0.02 * 0.02;
  closure_covariance.bottomRightCorner<3, 3>() *= 0.0035 * 0.0035;
  LoopClosureRun run;
  bool wrong_closure_added = false;
  size_t known_keyframes = 0;
  const Status status = simulation->run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) {
    (void)frontend_only->push(sensor.name, message);
    (void)session->push(sensor.name, message);
    const KeyframeGraphUpdate update = backend.process(session.get()).value();
    if (update.corrected_session) ++run.corrections;
    if (update.loop_batch) run.loop_batches.push_back(*backend.keyframe_time(backend.keyframe_ids().back()));
    const std::vector<uint64_t> ids = backend.keyframe_ids();
    for (; known_keyframes < ids.size(); ++known_keyframes) {
      const uint64_t id = ids[known_keyframes];
      const SE3 truth = trajectory.sample(*backend.keyframe_time(id)).T_world_body;
      for (uint64_t older = 0; older + 40 < id; ++older) {
        const SE3 older_truth = trajectory.sample(*backend.keyframe_time(older)).T_world_body;
        if ((older_truth.translation() - truth.translation()).norm() > 0.8) continue;
        SE3::Tangent noise;
        for (int k = 0; k < 6; ++k) noise(k) = normal(random) * (k < 3 ? 0.02 : 0.0035);
        EXPECT_TRUE(backend.add_loop_closure(older, id, older_truth.inverse() * truth * SE3::exp(noise), closure_covariance).ok());
        ++run.closures;
        if (!wrong_closure_added) {
          EXPECT_TRUE(backend.add_loop_closure(older / 2, id, SE3(SO3(), Eigen::Vector3d(5.0, 0.0, 0.0)), closure_covariance).ok());
          wrong_closure_added = true;
        }
        break;
      }
    }
    return ok_status();
  });
  EXPECT_TRUE(status.ok());
  session->flush();
  frontend_only->flush();
  EXPECT_TRUE(backend.process(session.get()).ok());
  EXPECT_TRUE(backend.smoother().wait_for_batch().ok());

  std::vector<std::pair<SE3, SE3>> optimized, dead_reckoned;
  for (uint64_t id : backend.keyframe_ids()) {
    optimized.emplace_back(*backend.optimized_pose(id), trajectory.sample(*backend.keyframe_time(id)).T_world_body);
  }
  for (const msgs::Keyframe& keyframe : frontend_only_keyframes) {
    dead_reckoned.emplace_back(keyframe.T_world_body.to_se3(), trajectory.sample(keyframe.timestamp).T_world_body);
  }
  run.keyframes = optimized.size();
  run.optimized_rmse = position_rmse(optimized);
  run.dead_reckoned_rmse = position_rmse(dead_reckoned);
  // The live frontend estimate at the end, with and without the backend's corrections, aligned
  // like the keyframes (by the first keyframe).
  const auto final_error = [&](const Frontend& fused, const SE3& first_keyframe, Timestamp first_time) {
    const SE3 alignment = trajectory.sample(first_time).T_world_body * first_keyframe.inverse();
    const msgs::PoseEstimate pose = *fused.latest_pose();
    return ((alignment * pose.T_world_body.to_se3()).translation() - trajectory.sample(pose.timestamp).T_world_body.translation()).norm();
  };
  run.final_with_backend = final_error(*session, *backend.frontend_pose(0), *backend.keyframe_time(0));
  run.final_dead_reckoned =
      final_error(*frontend_only, frontend_only_keyframes.front().T_world_body.to_se3(), frontend_only_keyframes.front().timestamp);
  std::printf("warehouse, IMU + wheels, %zu keyframes, %d loop closures, %zu loop batches (at most one per %.0f s): keyframe position RMSE "
              "%.3f m dead reckoning, %.3f m with the backend; final frontend error %.3f m -> %.3f m (%d corrections)\n",
              run.keyframes, run.closures, run.loop_batches.size(), loop_batch_interval_s, run.dead_reckoned_rmse, run.optimized_rmse,
              run.final_dead_reckoned, run.final_with_backend, run.corrections);
  return run;
}

TEST(KeyframeGraph, LoopClosuresCorrectTheDeadReckonedTrajectoryAndTheFrontend) {
  const LoopClosureRun run = run_warehouse_loop_closures(0.0);
  EXPECT_GT(run.closures, 20);
  EXPECT_GT(run.keyframes, 100u);
  EXPECT_LT(run.optimized_rmse, 0.4 * run.dead_reckoned_rmse);
  EXPECT_LT(run.final_with_backend, 0.1 * run.final_dead_reckoned);
  EXPECT_GT(run.corrections, 100);
  EXPECT_GE(run.loop_batches.size(), 20u);  // one per update with loop closures
}

// Loop batches at most every 10 s: the closures in between wait for the next one, and the
// trajectory and the live estimate end up as well corrected.
TEST(KeyframeGraph, LoopBatchesKeepTheirIntervalAndCorrectAsWell) {
  const LoopClosureRun run = run_warehouse_loop_closures(10.0);
  EXPECT_GT(run.closures, 20);
  ASSERT_GE(run.loop_batches.size(), 2u);
  EXPECT_LT(run.loop_batches.size(), static_cast<size_t>(run.closures) / 2);
  for (size_t i = 1; i < run.loop_batches.size(); ++i) EXPECT_GE((run.loop_batches[i] - run.loop_batches[i - 1]).seconds(), 10.0);
  EXPECT_LT(run.optimized_rmse, 0.4 * run.dead_reckoned_rmse);
  EXPECT_LT(run.final_with_backend, 0.1 * run.final_dead_reckoned);
}

TEST(KeyframeGraph, GnssFixesAttachToKeyframesAndBadInputIsRefused) {
  KeyframeGraph backend;
  msgs::Keyframe first;
  first.keyframe_id = 0;
  first.timestamp = Timestamp::from_nanoseconds(1'000'000'000);
  first.pose_covariance = msgs::Matrix6d::Identity();
  ASSERT_TRUE(backend.add_keyframe(first).ok());
  msgs::Keyframe second = first;
  second.keyframe_id = 1;
  second.timestamp = Timestamp::from_nanoseconds(2'000'000'000);
  second.previous_keyframe_id = 0;
  second.T_previous_current = msgs::Pose::from_se3(SE3(SO3(), Eigen::Vector3d(1.0, 0.0, 0.0)));
  second.relative_covariance = 0.01 * msgs::Matrix6d::Identity();
  ASSERT_TRUE(backend.add_keyframe(second).ok());
  // A fix 20 ms after keyframe 1 says it is at x = 3 (very confident): it pulls keyframe 1 there.
  ASSERT_TRUE(backend.add_gps(Timestamp::from_nanoseconds(2'020'000'000), {3.0, 0.0, 0.0}, 1e-6 * Eigen::Matrix3d::Identity()).ok());
  // A fix far from every keyframe is dropped once later keyframes show none will come.
  ASSERT_TRUE(backend.add_gps(Timestamp::from_nanoseconds(1'500'000'000), {9.0, 9.0, 9.0}, Eigen::Matrix3d::Identity()).ok());
  const KeyframeGraphUpdate update = backend.process().value();
  EXPECT_EQ(update.fixes_dropped, 1);
  EXPECT_NEAR(backend.optimized_pose(1)->translation().x(), 3.0, 1e-3);

  EXPECT_THAT(backend.add_keyframe(second).error().message, HasSubstr("already added"));
  msgs::Keyframe orphan = second;
  orphan.keyframe_id = 5;
  orphan.previous_keyframe_id = 4;
  EXPECT_THAT(backend.add_keyframe(orphan).error().message, HasSubstr("previous keyframe 4 is unknown"));
  EXPECT_THAT(backend.add_loop_closure(0, 9, SE3(), msgs::Matrix6d::Identity()).error().message, HasSubstr("keyframe 9 is unknown"));
  EXPECT_THAT(backend.add_loop_closure(0, 1, SE3(), -msgs::Matrix6d::Identity()).error().message, HasSubstr("covariance"));
  EXPECT_FALSE(backend.add_gps(first.timestamp, Eigen::Vector3d::Constant(std::nan("")), Eigen::Matrix3d::Identity()).ok());
  EXPECT_EQ(backend.keyframe_ids().size(), 2u);

  // A fix (sigma 1 cm) of an antenna 2 m ahead of keyframe 0 (the lever arm carried through the
  // motion since the keyframe) at x = 4.05: keyframe 0, at 2.0 by the odometry (sigma 0.1 m)
  // from keyframe 1, moves to 2.05 (weighted: 2.0495).
  ASSERT_TRUE(backend.add_gps_at_keyframe(0, {4.05, 0.0, 0.0}, 1e-4 * Eigen::Matrix3d::Identity(), {2.0, 0.0, 0.0}).ok());
  ASSERT_TRUE(backend.process().ok());
  ASSERT_TRUE(backend.smoother().wait_for_batch().ok());
  EXPECT_NEAR(backend.optimized_pose(0)->translation().x(), 2.0495, 2e-3);
  EXPECT_THAT(backend.add_gps_at_keyframe(7, {0.0, 0.0, 0.0}, Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero()).error().message,
              HasSubstr("keyframe 7 is unknown"));
  EXPECT_THAT(backend.add_gps_at_keyframe(0, {0.0, 0.0, 0.0}, -Eigen::Matrix3d::Identity(), Eigen::Vector3d::Zero()).error().message,
              HasSubstr("covariance"));
}

// Fixes whose error wanders (a first-order Gauss-Markov process, 5 s, 0.5 m, as a float RTK
// solution's) on a 300 m drive with odometry of 3 cm and 0.5 mrad every 10 m: taken as
// independent they bend the trajectory along the error; as a correlated error (E variables) the
// shape follows the odometry and the world the fixes' average.
struct GnssDrive {
  double shape_rmse = 0.0;  // keyframe positions SE3-aligned onto the truth
  double world_rmse = 0.0;
};

GnssDrive drive_with_correlated_fixes(double error_correlation_s) {
  KeyframeGraphConfig config;
  config.smoother.background_batch = false;
  config.gnss_error_correlation_s = error_correlation_s;
  config.first_position_sigma = 100.0;
  KeyframeGraph backend(config);
  std::mt19937 random(11);
  std::normal_distribution<double> normal(0.0, 1.0);
  const double sigma = 0.5, tau = 5.0, rate = 5.0;
  Eigen::Vector3d error(sigma * normal(random), sigma * normal(random), sigma * normal(random));
  const auto truth = [](double t) { return SE3(SO3::exp(Eigen::Vector3d(0.0, 0.0, 0.01 * t)), Eigen::Vector3d(10.0 * t, 0.05 * t * t, 0.0)); };
  const int keyframes = 30;
  for (int k = 0; k < keyframes; ++k) {
    msgs::Keyframe keyframe;
    keyframe.keyframe_id = static_cast<uint64_t>(k);
    keyframe.timestamp = Timestamp::from_seconds(100.0 + k);
    keyframe.T_world_body = msgs::Pose::from_se3(truth(k));
    keyframe.pose_covariance = 1e-4 * msgs::Matrix6d::Identity();
    if (k > 0) {
      keyframe.previous_keyframe_id = static_cast<uint64_t>(k - 1);
      keyframe.T_previous_current = msgs::Pose::from_se3(truth(k - 1).inverse() * truth(k));
      msgs::Matrix6d relative = msgs::Matrix6d::Identity() * 9e-4;  // 3 cm
      relative.bottomRightCorner<3, 3>() = Eigen::Matrix3d::Identity() * 2.5e-7;  // 0.5 mrad
      keyframe.relative_covariance = relative;
    }
    EXPECT_TRUE(backend.add_keyframe(keyframe).ok());
    for (int j = 0; j < static_cast<int>(rate); ++j) {
      const double a = std::exp(-1.0 / (rate * tau));
      for (int axis = 0; axis < 3; ++axis) error[axis] = a * error[axis] + std::sqrt(1.0 - a * a) * sigma * normal(random);
      const double after = j / rate;
      const SE3 T_keyframe_fix = truth(k).inverse() * truth(k + after);
      EXPECT_TRUE(backend.add_gps_at_keyframe(keyframe.keyframe_id, truth(k + after).translation() + error, sigma * sigma * Eigen::Matrix3d::Identity(),
                                              T_keyframe_fix.translation(), after).ok());
    }
    EXPECT_TRUE(backend.process().ok());
  }
  EXPECT_TRUE(backend.smoother().wait_for_batch().ok());
  Eigen::Matrix3Xd estimate(3, keyframes), reference(3, keyframes);
  for (int k = 0; k < keyframes; ++k) {
    estimate.col(k) = backend.optimized_pose(static_cast<uint64_t>(k))->translation();
    reference.col(k) = truth(k).translation();
  }
  GnssDrive drive;
  drive.world_rmse = std::sqrt((estimate - reference).colwise().squaredNorm().mean());
  const Eigen::Matrix4d alignment = Eigen::umeyama(estimate, reference, false);
  const Eigen::Matrix3Xd aligned = (alignment.topLeftCorner<3, 3>() * estimate).colwise() + alignment.topRightCorner<3, 1>();
  drive.shape_rmse = std::sqrt((aligned - reference).colwise().squaredNorm().mean());
  return drive;
}

TEST(KeyframeGraph, CorrelatedGnssErrorsLeaveTheShapeToTheOdometry) {
  const GnssDrive independent = drive_with_correlated_fixes(0.0);
  const GnssDrive correlated = drive_with_correlated_fixes(10.0);
  std::printf("fixes independent: shape %.3f m, world %.3f m; correlated error: shape %.3f m, world %.3f m\n", independent.shape_rmse,
              independent.world_rmse, correlated.shape_rmse, correlated.world_rmse);
  EXPECT_LT(correlated.shape_rmse, 0.3 * independent.shape_rmse);
  EXPECT_LT(correlated.world_rmse, independent.world_rmse * 1.1);
}

// Factors from elsewhere (visual_inertial_factors.hpp) join the keyframes; a value given again
// for a variable the graph has keeps the graph's estimate, and a new keyframe starts where the
// graph has its predecessor, not where the frontend put it.
TEST(KeyframeGraph, AddedFactorsJoinTheKeyframesAndKnownValuesKeepTheirEstimate) {
  KeyframeGraphConfig config;
  config.smoother.background_batch = false;
  KeyframeGraph graph(config);
  msgs::Keyframe first;
  first.keyframe_id = 0;
  first.timestamp = Timestamp::from_seconds(10.0);
  first.pose_covariance = Eigen::Matrix<double, 6, 6>::Identity() * 1e-6;
  ASSERT_TRUE(graph.add_keyframe(first).ok());
  graph::GraphUpdate update;
  update.values.insert(graph::L(7), Eigen::Vector3d(1.0, 2.0, 3.0));
  update.factors.emplace<graph::PriorFactorVector3>(graph::L(7), Eigen::Vector3d(1.0, 2.0, 3.0),
                                                    graph::GaussianNoise::from_sigmas(Eigen::Vector3d::Constant(0.1)).value());
  graph.add_factors(update);
  ASSERT_TRUE(graph.process().ok());
  graph::GraphUpdate again;
  again.values.insert(graph::L(7), Eigen::Vector3d(50.0, 50.0, 50.0));
  graph.add_factors(again);
  msgs::Keyframe second = first;
  second.keyframe_id = 1;
  second.timestamp = Timestamp::from_seconds(11.0);
  second.T_world_body = msgs::Pose::from_se3(SE3(SO3(), Eigen::Vector3d(5.0, 0.0, 0.0)));  // the frontend's world moved
  second.previous_keyframe_id = 0;
  second.T_previous_current = msgs::Pose::from_se3(SE3(SO3(), Eigen::Vector3d(1.0, 0.0, 0.0)));
  second.relative_covariance = Eigen::Matrix<double, 6, 6>::Identity() * 1e-4;
  EXPECT_NEAR((graph.initial_pose(second).translation() - Eigen::Vector3d(1.0, 0.0, 0.0)).norm(), 0.0, 1e-9);
  ASSERT_TRUE(graph.add_keyframe(second).ok());
  ASSERT_TRUE(graph.process().ok());
  EXPECT_NEAR((graph.smoother().estimate().at<Eigen::Vector3d>(graph::L(7)).value() - Eigen::Vector3d(1.0, 2.0, 3.0)).norm(), 0.0, 1e-6);
  EXPECT_NEAR((graph.optimized_pose(1)->translation() - Eigen::Vector3d(1.0, 0.0, 0.0)).norm(), 0.0, 1e-6);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
