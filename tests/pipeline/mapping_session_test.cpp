// MappingSession: IMU + LiDAR of the simulated urban_vehicle lap (OS1-64, 752 m, ends where it
// started) through the full pipeline: LiDAR-inertial odometry, keyframe graph, map, Scan
// Context loop closure correcting the Session; manual loop closures; bad sweeps.

#include <cmath>

#include <gtest/gtest.h>

#include "hanzo/fusion/pipeline/mapping_session.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"

namespace hanzo::fusion::pipeline {
namespace {

sim::Scenario imu_and_lidar(double duration_s = 0.0) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/urban_vehicle.yaml").value();
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& s) {
    return s.modality != config::SensorModality::kLidar && s.modality != config::SensorModality::kImu;
  });
  if (duration_s > 0) scenario.duration = duration_s;
  scenario.num_threads = 0;
  return scenario;
}

// The start-to-end motion: independent of the world frame (the Session's differs from the
// truth's by its unknown initial yaw).
double start_to_end_error(const SE3& estimate_start, const SE3& estimate_end, const SE3& truth_start, const SE3& truth_end) {
  return ((estimate_start.inverse() * estimate_end).translation() - (truth_start.inverse() * truth_end).translation()).norm();
}

TEST(MappingSession, UrbanLapClosesTheLoopMapsAndTakesManualLoopClosures) {
  const sim::Scenario scenario = imu_and_lidar();
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  auto mapping = MappingSession::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario)).value();
  const sim::SplineTrajectory& trajectory = simulation->trajectory();

  std::optional<msgs::PoseEstimate> first, latest;
  mapping->set_pose_callback([&](const msgs::PoseEstimate& pose) {
    if (!first && (pose.timestamp - trajectory.start_time()).seconds() > 2.0) first = pose;
    latest = pose;
  });
  std::vector<msgs::Keyframe> keyframes;
  mapping->set_keyframe_callback([&](const msgs::Keyframe& keyframe) { keyframes.push_back(keyframe); });
  uint64_t added_updates = 0, replacements = 0;
  mapping->set_map_update_callback([&](const msgs::MapUpdate& update) {
    (update.full_replacement ? replacements : added_updates) += 1;
    EXPECT_TRUE(update.added_points.has_value());
  });
  const Status status = simulation->run(
      [&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status { return mapping->push(sensor.name, message); });
  ASSERT_TRUE(status.ok()) << status.error().message;
  mapping->flush();
  ASSERT_TRUE(first && latest);

  const MappingSummary summary = mapping->mapping_summary();
  EXPECT_GT(summary.scans_registered, 700U);
  EXPECT_LE(summary.scans_refused, 15U);
  EXPECT_GT(summary.map_keyframes, 60U);
  // LiDAR-inertial odometry drifts little here (< 0.2 m over the lap); the return to the start
  // is found and verified all the same, and the look-alike streets are not.
  EXPECT_GE(summary.loop_closures, 1U);
  EXPECT_LE(summary.loop_closures, 5U);
  EXPECT_EQ(added_updates, summary.map_keyframes);
  const double error_at_end = start_to_end_error(first->T_world_body.to_se3(), latest->T_world_body.to_se3(),
                                                 trajectory.sample(first->timestamp).T_world_body,
                                                 trajectory.sample(latest->timestamp).T_world_body);
  EXPECT_LT(error_at_end, 0.15);

  // The LiDAR's counters in the Session summary.
  const SessionSummary session_summary = mapping->summary();
  const auto lidar = std::find_if(session_summary.sensors.begin(), session_summary.sensors.end(),
                                  [](const SensorStatistics& s) { return s.modality == config::SensorModality::kLidar; });
  ASSERT_NE(lidar, session_summary.sensors.end());
  EXPECT_EQ(lidar->fused, summary.scans_registered);
  EXPECT_EQ(lidar->received, summary.scans_received);

  // The map: points along the whole lap and a 2D occupancy grid.
  const msgs::FusionMap map = mapping->map();
  ASSERT_TRUE(map.points.has_value());
  EXPECT_GT(map.points->points.size(), 10000U);
  EXPECT_TRUE(map.occupancy.has_value());
  EXPECT_EQ(map.version, summary.map_version);

  // Manual loop closures. Bad requests change nothing.
  ASSERT_GT(keyframes.size(), 60U);
  const uint64_t first_id = keyframes[5].keyframe_id, last_id = keyframes.back().keyframe_id;
  LoopClosureRequest half_request;
  half_request.from_keyframe = first_id;
  EXPECT_FALSE(mapping->close_loop(half_request).ok());
  LoopClosureRequest unknown;
  unknown.from_keyframe = 999999;
  unknown.to_keyframe = last_id;
  const auto refused = mapping->close_loop(unknown);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("999999"), std::string::npos) << refused.error().message;
  EXPECT_EQ(mapping->mapping_summary().manual_loop_closures, 0U);
  // Registered: the search for the newest map keyframe finds the start again.
  const auto searched = mapping->close_loop({});
  ASSERT_TRUE(searched.ok()) << searched.error().message;
  EXPECT_TRUE(searched->registered);
  EXPECT_LT(searched->inlier_rmse, 0.1);
  EXPECT_LT(searched->correction_m, 0.05) << "it agrees with the closure already made";
  // Given: a relative pose 1 m off the graph's pulls the latest keyframe (against the
  // closures already made), the Session and the map.
  const SE3 graph_relative = mapping->keyframe_pose(first_id)->inverse() * *mapping->keyframe_pose(last_id);
  LoopClosureRequest given;
  given.from_keyframe = first_id;
  given.to_keyframe = last_id;
  given.T_from_to = graph_relative * SE3(SO3(), Eigen::Vector3d(1.0, 0.0, 0.0));
  const uint64_t replacements_before = replacements;
  const auto closed = mapping->close_loop(given);
  ASSERT_TRUE(closed.ok()) << closed.error().message;
  EXPECT_FALSE(closed->registered);
  const double moved = (mapping->keyframe_pose(last_id)->translation() - (*mapping->keyframe_pose(first_id) * graph_relative).translation()).norm();
  EXPECT_GT(moved, 0.05);
  EXPECT_LT(moved, 1.0);
  EXPECT_EQ(mapping->mapping_summary().manual_loop_closures, 2U);
  EXPECT_GT(replacements, replacements_before) << "the map follows the moved keyframes";
  EXPECT_GT(mapping->mapping_summary().map_version, summary.map_version);
}

TEST(MappingSession, RefusesBadSweepsWithAReasonAndKeepsMapping) {
  const sim::Scenario scenario = imu_and_lidar(8.0);
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  auto mapping = MappingSession::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario)).value();
  std::optional<msgs::PointCloudMessage> previous;
  int refused = 0;
  const Status status = simulation->run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status {
    if (const auto* sweep = std::get_if<msgs::PointCloudMessage>(&message); sweep && previous) {
      const Status duplicate = mapping->push(sensor.name, msgs::SensorMessage(*previous));
      EXPECT_FALSE(duplicate.ok());
      if (!duplicate.ok()) {
        EXPECT_EQ(duplicate.error().message.rfind("duplicate", 0), 0U) << duplicate.error().message;
      }
      msgs::PointCloudMessage broken = *sweep;
      broken.points[3].x() = std::nanf("");
      const Status invalid = mapping->push(sensor.name, msgs::SensorMessage(broken));
      EXPECT_FALSE(invalid.ok());
      if (!invalid.ok()) {
        EXPECT_EQ(invalid.error().message.rfind("invalid", 0), 0U) << invalid.error().message;
      }
      refused += 2;
    }
    if (const auto* sweep = std::get_if<msgs::PointCloudMessage>(&message)) previous = *sweep;
    return mapping->push(sensor.name, message);
  });
  ASSERT_TRUE(status.ok()) << status.error().message;
  ASSERT_GT(refused, 100);
  const SessionSummary summary = mapping->summary();
  const auto lidar = std::find_if(summary.sensors.begin(), summary.sensors.end(),
                                  [](const SensorStatistics& s) { return s.modality == config::SensorModality::kLidar; });
  ASSERT_NE(lidar, summary.sensors.end());
  EXPECT_EQ(lidar->rejected.at("duplicate") + lidar->rejected.at("invalid"), static_cast<uint64_t>(refused));
  // The good sweeps after the 3 s standstill (alignment) registered all the same.
  EXPECT_GT(mapping->mapping_summary().scans_registered, 45U);
  EXPECT_GT(mapping->mapping_summary().map_keyframes, 2U);
}

TEST(MappingSession, AsynchronousRegistrationFusesTheSweepsLateAndKeepsTheTrack) {
  // The server's mode: sweeps registered on the session's worker thread, fused when the next
  // message comes (in the past, by rolling back). Pushed as fast as possible here: push() waits
  // when two sweeps queue up, so none is lost.
  const sim::Scenario scenario = imu_and_lidar(25.0);
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  MappingSessionConfig config;
  config.asynchronous_registration = true;
  auto mapping = MappingSession::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario), config).value();
  const sim::SplineTrajectory& trajectory = simulation->trajectory();
  std::optional<msgs::PoseEstimate> first, latest;
  mapping->set_pose_callback([&](const msgs::PoseEstimate& pose) {
    if (!first && (pose.timestamp - trajectory.start_time()).seconds() > 2.0) first = pose;
    if (!latest || latest->timestamp <= pose.timestamp) latest = pose;
  });
  const Status status = simulation->run(
      [&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status { return mapping->push(sensor.name, message); });
  ASSERT_TRUE(status.ok()) << status.error().message;
  mapping->flush();
  const MappingSummary summary = mapping->mapping_summary();
  EXPECT_EQ(summary.scans_received, 250U);
  EXPECT_GT(summary.scans_registered, 225U);  // all but those before the IMU's alignment
  EXPECT_GT(summary.map_keyframes, 15U);
  ASSERT_TRUE(first && latest);
  EXPECT_LT(start_to_end_error(first->T_world_body.to_se3(), latest->T_world_body.to_se3(), trajectory.sample(first->timestamp).T_world_body,
                               trajectory.sample(latest->timestamp).T_world_body),
            0.2);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
