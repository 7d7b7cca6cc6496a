// Several 3D LiDARs in one session: LidarSweepMerger's contract (which points join which sweep,
// frames, rings, waiting, late sweeps) and the simulated urban drive with two LiDARs that each
// see half the turn (front and back) against the front one alone.

#include <algorithm>
#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/pipeline/lidar_sweep_merger.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "pipeline/scenario_replay.hpp"

namespace hanzo::fusion::pipeline {
namespace {

const Timestamp kStart = Timestamp::from_seconds(100.0);

// A sweep of `count` points 10 m ahead of the sensor, spread over [0, length] s, rings 0..3.
msgs::PointCloudMessage sweep_at(Timestamp start, int count, double length, bool with_times = true) {
  msgs::PointCloudMessage sweep;
  sweep.timestamp = start;
  sweep.frame_id = "lidar";
  for (int i = 0; i < count; ++i) {
    sweep.points.emplace_back(10.0F, 0.01F * static_cast<float>(i), 0.0F);
    sweep.intensities.push_back(0.5F);
    sweep.ring_ids.push_back(static_cast<uint32_t>(i % 4));
    if (with_times) sweep.point_timestamps.push_back(start + Duration::from_seconds(length * i / std::max(1, count - 1)));
  }
  return sweep;
}

cloud::PointCloud primary_cloud(int count, double length) {
  return cloud::from_message(sweep_at(kStart, count, length)).value();
}

TEST(LidarSweepMerger, JoinsThePointsTimedInsideThePrimarySweepInThePrimaryFrame) {
  // The secondary sits 2 m behind the primary, turned half a turn: its points 10 m ahead are
  // 12 m behind the primary.
  const SE3 T_primary_secondary(SO3::exp(Eigen::Vector3d(0, 0, std::numbers::pi)), Eigen::Vector3d(-2.0, 0.0, 0.0));
  LidarSweepMerger merger({{"lidar_rear", T_primary_secondary}});
  // Secondary sweeps over [99.95, 100.05] and [100.05, 100.15]: the primary sweep [100, 100.1]
  // takes the second half of the first and the first half of the second.
  ASSERT_TRUE(merger.add(0, sweep_at(kStart - Duration::from_seconds(0.05), 11, 0.1)).ok());
  ASSERT_TRUE(merger.add(0, sweep_at(kStart + Duration::from_seconds(0.05), 11, 0.1)).ok());
  cloud::PointCloud primary = primary_cloud(20, 0.1);
  const std::size_t appended = merger.merge(primary, kStart);
  EXPECT_EQ(appended, 12U);  // 6 of each (the ends of the window included)
  ASSERT_EQ(primary.size(), 32U);
  ASSERT_EQ(primary.times.size(), 32U);
  ASSERT_EQ(primary.rings.size(), 32U);
  ASSERT_EQ(primary.intensities.size(), 32U);
  for (std::size_t i = 20; i < primary.size(); ++i) {
    EXPECT_NEAR(primary.positions[i].x(), -12.0F, 1e-4F);
    EXPECT_GE(primary.times[i], 0.0F);
    EXPECT_LE(primary.times[i], 0.1F + 1e-6F);
    EXPECT_GE(primary.rings[i], 4U) << "after the primary's rings 0..3";
  }
  // Times follow the secondary's clock: the first joined point is the old sweep's at 100.0 s.
  EXPECT_NEAR(primary.times[20], 0.0F, 1e-5F);
  // The first secondary sweep is used up (its first half was too old for this primary sweep).
  EXPECT_EQ(merger.statistics(0).merged_sweeps, 1U);
  EXPECT_EQ(merger.statistics(0).late_points, 5U);
  EXPECT_EQ(merger.statistics(0).merged_points, 12U);
  // The next primary sweep takes the rest of the second secondary sweep, nothing twice.
  cloud::PointCloud next = cloud::from_message(sweep_at(kStart + Duration::from_seconds(0.1), 20, 0.1)).value();
  EXPECT_EQ(merger.merge(next, kStart + Duration::from_seconds(0.1)), 5U);
  EXPECT_EQ(merger.statistics(0).merged_sweeps, 2U);
  EXPECT_EQ(merger.statistics(0).late_sweeps, 0U);
}

TEST(LidarSweepMerger, CropsInTheSecondarysOwnFrameAndCountsLateSweeps) {
  // 0.5 m from the secondary (its mount): cropped though 5.5 m from the primary.
  LidarSweepMerger merger({{"lidar_b", SE3(SO3(), Eigen::Vector3d(5.0, 0.0, 0.0))}});
  msgs::PointCloudMessage near = sweep_at(kStart, 5, 0.1);
  for (Eigen::Vector3f& point : near.points) point = Eigen::Vector3f(0.5F, 0.0F, 0.0F);
  ASSERT_TRUE(merger.add(0, near).ok());
  EXPECT_EQ(merger.statistics(0).late_sweeps, 1U) << "nothing in range to merge";
  // A sweep wholly before the primary sweep's window: late.
  ASSERT_TRUE(merger.add(0, sweep_at(kStart - Duration::from_seconds(0.5), 10, 0.1)).ok());
  cloud::PointCloud primary = primary_cloud(20, 0.1);
  EXPECT_EQ(merger.merge(primary, kStart), 0U);
  EXPECT_EQ(merger.statistics(0).late_sweeps, 2U);
  EXPECT_EQ(merger.statistics(0).late_points, 10U);
  // Bad input: refused, nothing kept.
  EXPECT_FALSE(merger.add(1, sweep_at(kStart, 10, 0.1)).ok());
  EXPECT_FALSE(merger.add(0, msgs::PointCloudMessage{}).ok());
  EXPECT_EQ(merger.statistics(0).sweeps, 2U);
}

TEST(LidarSweepMerger, UntimedPrimarySweepsTakeTheRecentSecondaryPointsWithoutTimes) {
  LidarSweepMerger merger({{"lidar_b", SE3()}});
  ASSERT_TRUE(merger.add(0, sweep_at(kStart - Duration::from_seconds(0.08), 10, 0.05)).ok());
  cloud::PointCloud primary = cloud::from_message(sweep_at(kStart, 20, 0.0, /*with_times=*/false)).value();
  ASSERT_FALSE(primary.has_times());
  EXPECT_EQ(merger.merge(primary, kStart), 10U);
  EXPECT_FALSE(primary.has_times());
  EXPECT_EQ(primary.rings.size(), primary.size());
}

TEST(LidarSweepMerger, WaitsForSecondariesThatHaveNotReachedTheSweepsEnd) {
  LidarSweepMerger merger({{"lidar_b", SE3()}}, {.wait_s = 0.2, .silent_after_s = 1.0});
  const Timestamp end = kStart + Duration::from_seconds(0.1);
  EXPECT_TRUE(merger.ready(end, end)) << "never heard: not waited for";
  ASSERT_TRUE(merger.add(0, sweep_at(kStart - Duration::from_seconds(0.05), 10, 0.1)).ok());  // reaches 100.05
  EXPECT_FALSE(merger.ready(end, end));
  EXPECT_FALSE(merger.ready(end, end + Duration::from_seconds(0.15)));
  EXPECT_TRUE(merger.ready(end, end + Duration::from_seconds(0.25))) << "waited wait_s";
  EXPECT_TRUE(merger.ready(kStart + Duration::from_seconds(2.0), kStart + Duration::from_seconds(2.0))) << "silent for over 1 s";
  ASSERT_TRUE(merger.add(0, sweep_at(kStart + Duration::from_seconds(0.05), 10, 0.1)).ok());  // reaches 100.15
  EXPECT_TRUE(merger.ready(end, end));
}

// The urban drive's first 40 s (IMU and LiDARs only) with VLP-16s that each see half the turn:
// one at the front looking ahead, one at the back looking behind. (With OS1-64s half a turn
// registers as well as both: 0.038 m SE3-aligned either way.)
sim::Scenario half_view_lidars(bool with_rear) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/urban_vehicle.yaml").value();
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& s) {
    return s.modality != config::SensorModality::kLidar && s.modality != config::SensorModality::kImu;
  });
  scenario.duration = 40.0;
  scenario.num_threads = 0;
  auto lidar = std::find_if(scenario.sensors.begin(), scenario.sensors.end(),
                            [](const sim::ScenarioSensor& s) { return s.modality == config::SensorModality::kLidar; });
  auto& front = std::get<sim::LidarSimulatorConfig>(lidar->simulator);
  front.pattern = sim::LidarPattern::preset(sim::LidarModel::kVelodyneVlp16);
  front.pattern.horizontal_fov = std::numbers::pi;
  if (with_rear) {
    sim::ScenarioSensor rear = *lidar;
    rear.name = "lidar_rear";
    rear.topic = "/sensors/lidar_rear";
    rear.T_body_sensor = SE3(SO3::exp(Eigen::Vector3d(0, 0, std::numbers::pi)), Eigen::Vector3d(-1.2, 0.1, 1.4));
    auto& simulator = std::get<sim::LidarSimulatorConfig>(rear.simulator);
    simulator.T_body_lidar = rear.T_body_sensor;
    simulator.frame_id = rear.name;
    simulator.seed = 7;
    scenario.sensors.push_back(rear);
  }
  return scenario;
}

struct DriveResult {
  double yaw_aligned_rmse = 0.0;  // m
  double se3_aligned_rmse = 0.0;  // m: the shape, without the start's tilt
  uint64_t scans_registered = 0;
  SessionSummary summary;
};

DriveResult drive(bool with_rear) {
  const sim::Scenario scenario = half_view_lidars(with_rear);
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  auto session = Session::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario)).value();
  const testing::ReplayedTrajectories run = testing::replay(*simulation, *session);
  DriveResult result;
  result.yaw_aligned_rmse = eval::compute_ape(run.truth, run.estimate, {.alignment = eval::Alignment::kYaw}).value().statistics.rmse;
  result.se3_aligned_rmse = eval::compute_ape(run.truth, run.estimate, {.alignment = eval::Alignment::kSE3}).value().statistics.rmse;
  result.scans_registered = session->mapping_summary().scans_registered;
  result.summary = session->summary();
  return result;
}

TEST(MultiLidarSession, TwoHalfViewLidarsTogetherBeatTheFrontOneAlone) {
  const DriveResult front = drive(false);
  const DriveResult both = drive(true);
  RecordProperty("front_only_rmse_m", std::to_string(front.yaw_aligned_rmse));
  RecordProperty("both_rmse_m", std::to_string(both.yaw_aligned_rmse));
  EXPECT_LT(both.yaw_aligned_rmse, front.yaw_aligned_rmse) << "front " << front.yaw_aligned_rmse << " m, both " << both.yaw_aligned_rmse << " m";
  RecordProperty("front_only_se3_rmse_m", std::to_string(front.se3_aligned_rmse));
  RecordProperty("both_se3_rmse_m", std::to_string(both.se3_aligned_rmse));
  EXPECT_LT(both.se3_aligned_rmse, front.se3_aligned_rmse) << "front " << front.se3_aligned_rmse << " m, both " << both.se3_aligned_rmse << " m";
  EXPECT_LT(both.yaw_aligned_rmse, 0.65);
  EXPECT_LT(both.se3_aligned_rmse, 0.045);
  EXPECT_GE(both.scans_registered + 5, front.scans_registered);
  // The rear LiDAR's sweeps joined the front one's, except while the IMU aligned (the front's
  // sweeps were refused then: "aligning"); it says so.
  const auto rear = std::find_if(both.summary.sensors.begin(), both.summary.sensors.end(),
                                 [](const SensorStatistics& s) { return s.name == "lidar_rear"; });
  ASSERT_NE(rear, both.summary.sensors.end());
  EXPECT_GT(rear->received, 350U);
  const auto front_lidar = std::find_if(both.summary.sensors.begin(), both.summary.sensors.end(),
                                        [](const SensorStatistics& s) { return s.name == "lidar"; });
  ASSERT_NE(front_lidar, both.summary.sensors.end());
  const auto aligning = front_lidar->rejected.find(Rejection::kAligning);
  const uint64_t front_aligning = aligning == front_lidar->rejected.end() ? 0U : aligning->second;
  const auto late = rear->rejected.find(Rejection::kNotFused);
  const uint64_t rear_late = late == rear->rejected.end() ? 0U : late->second;
  EXPECT_LE(rear_late, front_aligning + 1);
  EXPECT_EQ(rear->fused + rear_late, rear->received);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
