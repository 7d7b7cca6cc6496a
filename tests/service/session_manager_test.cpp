#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/eval/association.hpp"
#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/service/session_manager.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "service_fixtures.hpp"

namespace hanzo::fusion::service {
namespace {

using ::testing::HasSubstr;

const Principal kRobot{"robot", "acme",
                       static_cast<uint32_t>(Permission::kSessionWrite) | static_cast<uint32_t>(Permission::kSessionRead)};
const Principal kViewer{"viewer", "acme", static_cast<uint32_t>(Permission::kSessionRead)};
const Principal kOtherOrganization{"intruder", "globex", static_cast<uint32_t>(Permission::kAdmin)};

std::unique_ptr<SessionManager> open_manager(const std::filesystem::path& dir, SessionManagerConfig config = {}) {
  auto storage = open_storage("sqlite://" + (dir / "fusion.db").string());
  EXPECT_TRUE(storage.ok()) << storage.error().message;
  auto manager = SessionManager::create(config, std::move(storage).value(), std::make_shared<MetricsRegistry>());
  EXPECT_TRUE(manager.ok()) << manager.error().message;
  return manager.ok() ? std::move(manager).value() : nullptr;
}

SessionInfo create_sample_session(SessionManager& manager) {
  auto created = manager.create_session(kRobot, {"sample", testing::read_text("examples/data/fusion.yaml"), ""});
  EXPECT_TRUE(created.ok()) << created.error().message;
  return created.ok() ? created.value() : SessionInfo{};
}

std::vector<msgs::PoseEstimate> read_whole_trajectory(SessionManager& manager, const std::string& id, std::size_t page_size) {
  std::vector<msgs::PoseEstimate> poses;
  Timestamp after = Timestamp::from_nanoseconds(std::numeric_limits<int64_t>::min());
  while (true) {
    auto page = manager.trajectory(kViewer, id, after, page_size);
    EXPECT_TRUE(page.ok()) << page.error().message;
    if (!page.ok()) break;
    poses.insert(poses.end(), page->poses.begin(), page->poses.end());
    if (!page->next_after) break;
    after = *page->next_after;
  }
  return poses;
}

TEST(SessionManager, ReplaysTheSampleRecordingStoresEveryPoseAndMatchesGroundTruth) {
  auto manager = open_manager(testing::scratch_dir());
  ASSERT_TRUE(manager);
  const SessionInfo session = create_sample_session(*manager);
  EXPECT_EQ(session.organization, "acme");
  EXPECT_EQ(session.summary.sensors.size(), 3u);
  for (const testing::TimedMessage& message : testing::sample_recording()) {
    const ApiStatus pushed = manager->push(kRobot, session.id, message.sensor, message.message);
    ASSERT_TRUE(pushed.ok()) << pushed.error().message;
  }
  ASSERT_TRUE(manager->flush_storage().ok());
  const auto info = manager->session_info(kViewer, session.id);
  ASSERT_TRUE(info.ok());
  EXPECT_GT(info->summary.poses, 1800u);
  EXPECT_EQ(info->stored_poses, info->summary.poses) << "every emitted pose is stored";
  ASSERT_TRUE(info->latest_pose.has_value());
  EXPECT_EQ(info->stored_through, info->latest_pose->timestamp);

  const std::vector<msgs::PoseEstimate> stored = read_whole_trajectory(*manager, session.id, 499);
  ASSERT_EQ(stored.size(), info->summary.poses);
  io::Trajectory estimate;
  for (const msgs::PoseEstimate& pose : stored) {
    estimate.timestamps.push_back(pose.timestamp);
    estimate.poses.push_back(pose.T_world_body.to_se3().matrix());
  }
  auto reference = io::read_trajectory("examples/data/ground_truth.tum", io::TrajectoryFormat::kTum);
  ASSERT_TRUE(reference.ok());
  auto associated = eval::associate(reference.value(), estimate);
  ASSERT_TRUE(associated.ok()) << associated.error().message;
  auto ape = eval::compute_ape(associated->reference, associated->estimate, {.alignment = eval::Alignment::kSE3});
  ASSERT_TRUE(ape.ok());
  EXPECT_LT(ape->statistics.rmse, 0.2) << "the served trajectory is as accurate as `hanzo-fusion run` (Cli.RunReplaysTheSample...)";
}

// A server session of a 2D laser robot (the warehouse drive with a planar laser at 20 Hz, IMU and
// wheels, 20 s): the served trajectory follows the truth and the session's map has its grid.
TEST(SessionManager, ServesA2dLaserSession) {
  auto manager = open_manager(testing::scratch_dir());
  ASSERT_TRUE(manager);
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/warehouse_robot.yaml").value();
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& s) {
    return s.modality != config::SensorModality::kLidar && s.modality != config::SensorModality::kImu &&
           s.modality != config::SensorModality::kWheelOdometry;
  });
  for (sim::ScenarioSensor& entry : scenario.sensors) {
    if (entry.modality != config::SensorModality::kLidar) continue;
    auto& lidar = std::get<sim::LidarSimulatorConfig>(entry.simulator);
    lidar.pattern = sim::LidarPattern::preset(sim::LidarModel::kPlanarLaser);
    lidar.rate_hz = 20.0;
  }
  scenario.duration = 20.0;
  scenario.num_threads = 0;
  const config::FusionConfig fusion = sim::scenario_fusion_config(scenario);
  ASSERT_EQ(fusion.find_sensor("lidar")->type, config::kPlanarLaserType);
  const auto created =
      manager->create_session(kRobot, {"laser", config::to_yaml(fusion), calib::to_yaml(sim::scenario_calibration(scenario))});
  ASSERT_TRUE(created.ok()) << created.error().message;
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  ASSERT_TRUE(simulation
                  ->run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status {
                    const ApiStatus pushed = manager->push(kRobot, created->id, sensor.name, message);
                    EXPECT_TRUE(pushed.ok()) << pushed.error().message;
                    return ok_status();
                  })
                  .ok());
  ASSERT_TRUE(manager->flush_storage().ok());
  io::Trajectory estimate, truth;
  for (const msgs::PoseEstimate& pose : read_whole_trajectory(*manager, created->id, 1000)) {
    if (!estimate.timestamps.empty() && (pose.timestamp - estimate.timestamps.back()).seconds() < 0.1) continue;
    estimate.timestamps.push_back(pose.timestamp);
    estimate.poses.push_back(pose.T_world_body.to_se3().matrix());
    truth.timestamps.push_back(pose.timestamp);
    truth.poses.push_back(simulation->trajectory().sample(pose.timestamp).T_world_body.matrix());
  }
  auto ape = eval::compute_ape(truth, estimate, {.alignment = eval::Alignment::kSE3});
  ASSERT_TRUE(ape.ok()) << ape.error().message;
  std::printf("served 2D laser session, 20 s warehouse: %zu poses, SE3-aligned APE %.3f m\n", estimate.size(), ape->statistics.rmse);
  EXPECT_GT(estimate.size(), 150u);
  EXPECT_LT(ape->statistics.rmse, 0.1);
  const Principal map_reader{"viewer", "acme", static_cast<uint32_t>(Permission::kMapRead)};
  const auto map = manager->map(map_reader, created->id);
  ASSERT_TRUE(map.ok()) << map.error().message;
  ASSERT_TRUE(map->occupancy.has_value());
  EXPECT_GT(map->occupancy->size_x * map->occupancy->size_y, 1000u);
}

TEST(SessionManager, RejectedMessagesLeaveTheSessionIntact) {
  auto manager = open_manager(testing::scratch_dir());
  ASSERT_TRUE(manager);
  const SessionInfo session = create_sample_session(*manager);
  const std::vector<testing::TimedMessage> recording = testing::sample_recording();
  for (std::size_t i = 0; i < 400; ++i) ASSERT_TRUE(manager->push(kRobot, session.id, recording[i].sensor, recording[i].message).ok());
  const uint64_t poses_before = manager->session_info(kViewer, session.id)->summary.poses;

  // Out of order (an IMU message from the start), NaN, a sensor the session does not have.
  const testing::TimedMessage* first_imu = &recording.front();
  const ApiStatus late = manager->push(kRobot, session.id, "imu", first_imu->message);
  ASSERT_FALSE(late.ok());
  EXPECT_EQ(late.error().code, ErrorCode::kRejected);
  msgs::ImuMessage nan_message = std::get<msgs::ImuMessage>(recording[400].sensor == "imu" ? recording[400].message : recording[401].message);
  nan_message.angular_velocity.x() = std::numeric_limits<double>::quiet_NaN();
  const ApiStatus invalid = manager->push(kRobot, session.id, "imu", nan_message);
  ASSERT_FALSE(invalid.ok());
  // Typed reasons map to error codes: a malformed message or an unknown sensor is the request's
  // fault (invalid_argument, with the field), a message at the wrong time is rejected.
  EXPECT_EQ(invalid.error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(invalid.error().field, "message");
  EXPECT_THAT(invalid.error().message, HasSubstr("nan"));
  const ApiStatus unknown = manager->push(kRobot, session.id, "lidar", first_imu->message);
  EXPECT_EQ(unknown.error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(unknown.error().field, "sensor");
  // No sensor name: the only IMU is picked; a modality the session lacks is refused.
  EXPECT_EQ(manager->push(kRobot, session.id, "", msgs::RadarMessage{}).error().code, ErrorCode::kInvalidArgument);

  const auto after = manager->session_info(kViewer, session.id);
  EXPECT_EQ(after->summary.poses, poses_before);
  EXPECT_GE(after->summary.sensors[0].rejected_total(), 2u);
  // It carries on with the rest of the recording.
  for (std::size_t i = 400; i < recording.size(); ++i) {
    ASSERT_TRUE(manager->push(kRobot, session.id, "", recording[i].message).ok()) << i;
  }
  EXPECT_GT(manager->session_info(kViewer, session.id)->summary.poses, 1800u);
}

TEST(SessionManager, OrganizationsAndPermissionsAreEnforced) {
  auto manager = open_manager(testing::scratch_dir());
  ASSERT_TRUE(manager);
  const SessionInfo session = create_sample_session(*manager);
  const msgs::SensorMessage imu = testing::sample_recording().front().message;

  EXPECT_EQ(manager->session_info(kOtherOrganization, session.id).error().code, ErrorCode::kPermissionDenied);
  EXPECT_EQ(manager->push(kOtherOrganization, session.id, "imu", imu).error().code, ErrorCode::kPermissionDenied);
  EXPECT_EQ(manager->end_session(kOtherOrganization, session.id).error().code, ErrorCode::kPermissionDenied);
  EXPECT_TRUE(manager->list_sessions(kOtherOrganization)->empty());
  EXPECT_EQ(manager->push(kViewer, session.id, "imu", imu).error().code, ErrorCode::kPermissionDenied);
  EXPECT_EQ(manager->create_session(kViewer, {"x", testing::read_text("examples/data/fusion.yaml"), ""}).error().code,
            ErrorCode::kPermissionDenied);
  EXPECT_EQ(manager->session_info(kViewer, "0123456789abcdef").error().code, ErrorCode::kNotFound);
  EXPECT_EQ(manager->current_pose(kViewer, session.id).error().code, ErrorCode::kNotFound);  // no IMU data yet
  EXPECT_EQ(manager->list_sessions(kViewer)->size(), 1u);
  EXPECT_TRUE(manager->session_info(kViewer, session.id).ok());
}

TEST(SessionManager, BadConfigurationsAreRefusedWithTheField) {
  auto manager = open_manager(testing::scratch_dir());
  ASSERT_TRUE(manager);
  const auto no_sensors = manager->create_session(kRobot, {"", "fusion:\n  sensors: {}\n", ""});
  ASSERT_FALSE(no_sensors.ok());
  EXPECT_EQ(no_sensors.error().code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(no_sensors.error().message, HasSubstr("no sensors"));
  const auto negative = manager->create_session(kRobot, {"", "fusion:\n  sensors:\n    imu: {rate: -5}\n", ""});
  ASSERT_FALSE(negative.ok());
  EXPECT_THAT(negative.error().message, HasSubstr("rate"));
  const auto bad_calibration = manager->create_session(
      kRobot, {"", "fusion:\n  sensors:\n    imu: {rate: 100}\n", "calibration:\n  imu_to_body: {rotation: [2, 0, 0, 0]}\n"});
  ASSERT_FALSE(bad_calibration.ok());
  EXPECT_THAT(bad_calibration.error().message, HasSubstr("calibration"));
  EXPECT_EQ(manager->active_sessions(), 0u);
}

TEST(SessionManager, SensorsRegisterBeforeDataArrives) {
  auto manager = open_manager(testing::scratch_dir());
  ASSERT_TRUE(manager);
  auto created = manager->create_session(kRobot, {"", "fusion:\n  sensors:\n    imu: {rate: 100}\n", ""});
  ASSERT_TRUE(created.ok()) << created.error().message;
  const std::string id = created->id;
  auto registered = manager->register_sensor(kRobot, id, {"gnss", R"({"rate": 5, "topic": "/fix"})",
                                                          R"({"translation": [0.1, 0, 0.5]})"});
  ASSERT_TRUE(registered.ok()) << registered.error().message;
  ASSERT_EQ(registered->summary.sensors.size(), 2u);
  EXPECT_EQ(registered->summary.sensors[1].name, "gnss");
  EXPECT_THAT(registered->calibration_yaml, HasSubstr("gnss_to_body"));
  EXPECT_THAT(registered->config_yaml, HasSubstr("/fix"));

  EXPECT_EQ(manager->register_sensor(kRobot, id, {"gnss", "{rate: 5}", ""}).error().code, ErrorCode::kConflict);
  const auto bad = manager->register_sensor(kRobot, id, {"wheels", "{rate: -1}", ""});
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.error().code, ErrorCode::kInvalidArgument);
  EXPECT_THAT(bad.error().message, HasSubstr("rate"));
  EXPECT_EQ(manager->register_sensor(kRobot, id, {"wheels", "{rate: [", ""}).error().code, ErrorCode::kInvalidArgument);
  EXPECT_EQ(manager->register_sensor(kViewer, id, {"wheels", "{rate: 50}", ""}).error().code, ErrorCode::kPermissionDenied);

  ASSERT_TRUE(manager->push(kRobot, id, "imu", testing::sample_recording().front().message).ok());
  EXPECT_EQ(manager->register_sensor(kRobot, id, {"wheels", "{rate: 50}", ""}).error().code, ErrorCode::kConflict);
}

TEST(SessionManager, RestartRestoresSessionsAndTheirTrajectories) {
  const auto dir = testing::scratch_dir();
  const std::vector<testing::TimedMessage> recording = testing::sample_recording();
  const std::size_t half = recording.size() / 2;
  std::string id;
  uint64_t stored = 0;
  {
    auto manager = open_manager(dir);
    ASSERT_TRUE(manager);
    id = create_sample_session(*manager).id;
    ASSERT_TRUE(manager->register_sensor(kRobot, id, {"radar", "{rate: 10}", ""}).ok());
    for (std::size_t i = 0; i < half; ++i) ASSERT_TRUE(manager->push(kRobot, id, recording[i].sensor, recording[i].message).ok());
    ASSERT_TRUE(manager->flush_storage().ok());
    stored = manager->session_info(kRobot, id)->stored_poses;
    EXPECT_GT(stored, 500u);
  }
  auto manager = open_manager(dir);
  ASSERT_TRUE(manager);
  EXPECT_EQ(manager->active_sessions(), 1u);
  const auto info = manager->session_info(kViewer, id);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->stored_poses, stored);
  EXPECT_EQ(info->summary.sensors.size(), 4u) << "the registered sensor is part of the stored configuration";
  EXPECT_EQ(read_whole_trajectory(*manager, id, 10000).size(), stored);
  // The restored session runs again (its filter starts afresh).
  for (std::size_t i = half; i < recording.size(); ++i) ASSERT_TRUE(manager->push(kRobot, id, recording[i].sensor, recording[i].message).ok());
  ASSERT_TRUE(manager->flush_storage().ok());
  EXPECT_GT(manager->session_info(kViewer, id)->stored_poses, stored + 500);
}

TEST(SessionManager, PosesAcknowledgedAsStoredSurviveKillNine) {
  const auto dir = testing::scratch_dir();
  int pipe_fds[2];
  ASSERT_EQ(pipe(pipe_fds), 0);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    close(pipe_fds[0]);
    SessionManagerConfig config;
    config.storage_flush_interval = std::chrono::milliseconds(5);
    auto manager = open_manager(dir, config);
    if (!manager) _exit(3);
    const std::string id = create_sample_session(*manager).id;
    const std::vector<testing::TimedMessage> recording = testing::sample_recording();
    for (std::size_t i = 0;; ++i) {
      const testing::TimedMessage& message = recording[i % recording.size()];
      if (i >= recording.size()) {
        // Loop the recording forever at later times (the server is killed while it runs).
        msgs::SensorMessage shifted = message.message;
        std::visit([&](auto& m) { m.timestamp = m.timestamp + Duration::from_nanoseconds(int64_t(i / recording.size()) * 30'000'000'000LL); }, shifted);
        (void)manager->push(kRobot, id, message.sensor, shifted);
      } else {
        (void)manager->push(kRobot, id, message.sensor, message.message);
      }
      const auto info = manager->session_info(kRobot, id);
      const int64_t report[2] = {static_cast<int64_t>(info->stored_poses),
                                 info->stored_through ? info->stored_through->nanoseconds() : 0};
      if (write(pipe_fds[1], report, sizeof(report)) != sizeof(report)) _exit(5);
    }
  }
  close(pipe_fds[1]);
  int64_t report[2] = {0, 0};
  while (report[0] < 3000) ASSERT_EQ(read(pipe_fds[0], report, sizeof(report)), static_cast<ssize_t>(sizeof(report)));
  kill(child, SIGKILL);
  waitpid(child, nullptr, 0);
  int64_t more[2];
  while (read(pipe_fds[0], more, sizeof(more)) == static_cast<ssize_t>(sizeof(more))) std::copy(more, more + 2, report);
  close(pipe_fds[0]);

  auto manager = open_manager(dir);
  ASSERT_TRUE(manager);
  auto sessions = manager->list_sessions(kViewer);
  ASSERT_TRUE(sessions.ok());
  ASSERT_EQ(sessions->size(), 1u);
  EXPECT_GE(sessions->front().stored_poses, static_cast<uint64_t>(report[0])) << "acknowledged poses were lost";
  ASSERT_TRUE(sessions->front().stored_through.has_value());
  EXPECT_GE(sessions->front().stored_through->nanoseconds(), report[1]);
}

TEST(SessionManager, SlowSubscribersLoseTheOldestPosesNeverBlockFusion) {
  SessionManagerConfig config;
  config.subscriber_queue_capacity = 16;
  auto manager = open_manager(testing::scratch_dir(), config);
  ASSERT_TRUE(manager);
  const SessionInfo session = create_sample_session(*manager);
  auto subscription = manager->subscribe_poses(kViewer, session.id);
  ASSERT_TRUE(subscription.ok());
  EXPECT_EQ(manager->subscribe_poses(kOtherOrganization, session.id).error().code, ErrorCode::kPermissionDenied);
  for (const testing::TimedMessage& message : testing::sample_recording()) {
    ASSERT_TRUE(manager->push(kRobot, session.id, message.sensor, message.message).ok());
  }
  const auto info = manager->session_info(kViewer, session.id);
  const std::shared_ptr<PoseSubscription>& queue = subscription.value();
  EXPECT_EQ(queue->depth(), 16u);
  EXPECT_EQ(queue->dropped(), info->summary.poses - 16);
  // The newest 16 remain, oldest first, ending with the latest pose.
  std::optional<msgs::PoseEstimate> last;
  while (auto pose = queue->pop(std::chrono::milliseconds(0))) last = pose;
  ASSERT_TRUE(last.has_value());
  EXPECT_EQ(last->timestamp, info->latest_pose->timestamp);

  const auto ended = manager->end_session(kRobot, session.id);
  ASSERT_TRUE(ended.ok());
  EXPECT_TRUE(ended->ended.has_value());
  EXPECT_TRUE(queue->closed());
  EXPECT_EQ(manager->end_session(kRobot, session.id).error().code, ErrorCode::kConflict);
  EXPECT_EQ(manager->push(kRobot, session.id, "imu", testing::sample_recording().back().message).error().code, ErrorCode::kConflict);
  EXPECT_EQ(manager->trajectory(kViewer, session.id, Timestamp::from_nanoseconds(0), 5)->poses.size(), 5u)
      << "an ended session's trajectory stays readable";
  EXPECT_EQ(manager->active_sessions(), 0u);
}

}  // namespace
}  // namespace hanzo::fusion::service
