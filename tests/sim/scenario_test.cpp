// Scenarios: the shipped scenario files load, a run merges every sensor in time order with
// valid messages at the configured rates, runs are reproducible, and bad files are rejected
// with file, line and key.

#include <cmath>
#include <functional>
#include <map>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/msgs/validate.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"

namespace hanzo::fusion::sim {
namespace {

using ::testing::HasSubstr;

TEST(Scenario, ShippedScenariosLoadWithTheirSensorsAndFaults) {
  const Result<Scenario> warehouse = load_scenario("examples/scenarios/warehouse_robot.yaml");
  ASSERT_TRUE(warehouse) << warehouse.error().message;
  EXPECT_EQ(warehouse->sensors.size(), 4U);
  EXPECT_EQ(warehouse->world.moving_boxes.size(), 3U);
  const auto& wheels = std::get<WheelOdometrySimulatorConfig>(warehouse->sensors[3].simulator);
  ASSERT_EQ(wheels.slips.size(), 1U);
  EXPECT_EQ(wheels.slips[0].start, warehouse->start_time + Duration::from_seconds(25.0));

  const Result<Scenario> urban = load_scenario("examples/scenarios/urban_vehicle.yaml");
  ASSERT_TRUE(urban) << urban.error().message;
  EXPECT_GT(urban->world.boxes.size(), 30U);  // the generated city
  const auto& gnss = std::get<GnssSimulatorConfig>(urban->sensors[2].simulator);
  EXPECT_EQ(gnss.episodes.size(), 2U);
  EXPECT_EQ(std::get<LidarSimulatorConfig>(urban->sensors[1].simulator).weather.size(), 1U);

  const Result<Scenario> van = load_scenario("examples/scenarios/delivery_van.yaml");
  ASSERT_TRUE(van) << van.error().message;
  ASSERT_EQ(van->sensors.size(), 5U);  // imu, lidar, gnss, wheels, radar
  EXPECT_EQ(std::get<GnssSimulatorConfig>(van->sensors[2].simulator).episodes.size(), 1U);  // indoors: the outage
  EXPECT_EQ(std::get<LidarSimulatorConfig>(van->sensors[1].simulator).weather.size(), 1U);  // the rain

  for (const char* name : {"drone", "ar_handheld", "handheld_lidar", "delivery_van"}) {
    const Result<Scenario> scenario = load_scenario(std::string("examples/scenarios/") + name + ".yaml");
    ASSERT_TRUE(scenario) << scenario.error().message;
    const Result<SplineTrajectory> trajectory = make_trajectory(*scenario);
    ASSERT_TRUE(trajectory) << name;
    // Every scenario starts still (a filter's static alignment): a handheld device too, though
    // its holder looks around once walking.
    const Timestamp start = trajectory->start_time();
    for (double t = 0.1; t < 1.5; t += 0.1) {
      const TrajectorySample sample = trajectory->sample(start + Duration::from_seconds(t));
      EXPECT_LT(sample.angular_velocity_body.norm(), 1e-6) << name << " at " << t << " s";
      EXPECT_LT(sample.velocity_world.norm(), 1e-6) << name << " at " << t << " s";
    }
    EXPECT_TRUE(calib::validate(scenario_calibration(*scenario))) << name;
    EXPECT_TRUE(config::validate(scenario_fusion_config(*scenario))) << name;
  }
}

TEST(Scenario, StationsHoldTheRigStillAtEachPoseAndMoveBetween) {
  const Result<Scenario> scenario = load_scenario("examples/scenarios/camera_lidar_board.yaml");
  ASSERT_TRUE(scenario) << scenario.error().message;
  ASSERT_EQ(scenario->trajectory_type, TrajectoryType::kStations);
  const StationsTrajectoryConfig& config = scenario->stations;
  ASSERT_EQ(config.stations.size(), 10U);
  const Result<SplineTrajectory> trajectory = make_trajectory(*scenario);
  ASSERT_TRUE(trajectory) << trajectory.error().message;
  const double leg = config.hold + config.move;
  EXPECT_NEAR((trajectory->end_time() - trajectory->start_time()).seconds(), 10 * config.hold + 9 * config.move, config.knot_spacing);
  for (std::size_t i = 0; i < config.stations.size(); ++i) {
    const StationPose& station = config.stations[i];
    const SO3 expected = SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), station.roll_pitch_yaw.z()) *
                         SO3::from_axis_angle(Eigen::Vector3d::UnitY(), station.roll_pitch_yaw.y()) *
                         SO3::from_axis_angle(Eigen::Vector3d::UnitX(), station.roll_pitch_yaw.x());
    // Exactly at the station and still for hold - 3 knot spacings.
    for (double t = i * leg + 2.0 * config.knot_spacing; t <= i * leg + config.hold - 1.0 * config.knot_spacing; t += 0.1) {
      const TrajectorySample sample = trajectory->sample(trajectory->start_time() + Duration::from_seconds(t));
      EXPECT_LT((sample.T_world_body.translation() - station.position).norm(), 1e-9) << i << " at " << t;
      EXPECT_LT((sample.T_world_body.rotation().inverse() * expected).angle(), 1e-9) << i << " at " << t;
      EXPECT_LT(sample.velocity_world.norm() + sample.angular_velocity_body.norm(), 1e-9) << i << " at " << t;
    }
    if (i + 1 < config.stations.size()) {  // moving halfway to the next
      const TrajectorySample between = trajectory->sample(trajectory->start_time() + Duration::from_seconds(i * leg + config.hold + 0.5 * config.move));
      EXPECT_GT(between.velocity_world.norm() + between.angular_velocity_body.norm(), 0.1) << i;
    }
  }
  StationsTrajectoryConfig bad = config;
  bad.hold = 0.1;
  const Result<SplineTrajectory> short_hold = make_stations_trajectory(trajectory->start_time(), bad);
  ASSERT_FALSE(short_hold);
  EXPECT_THAT(short_hold.error().message, HasSubstr("hold: expected >= 4 knot spacings"));
}

struct RecordedRun {
  std::vector<std::string> sensors;
  std::vector<msgs::SensorMessage> messages;
};

RecordedRun record(Scenario scenario, double seconds) {
  scenario.duration = seconds;
  auto simulation = ScenarioSimulation::create(std::move(scenario));
  EXPECT_TRUE(simulation);
  RecordedRun run;
  const Status status = (*simulation)->run([&run](const ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status {
    run.sensors.push_back(sensor.name);
    run.messages.push_back(std::move(message));
    return ok_status();
  });
  EXPECT_TRUE(status);
  return run;
}

TEST(ScenarioSimulation, MergesAllSensorsInTimeOrderAtTheirRates) {
  const Result<Scenario> urban = load_scenario("examples/scenarios/urban_vehicle.yaml");
  ASSERT_TRUE(urban);
  const RecordedRun run = record(*urban, 1.0);
  std::map<std::string, int> counts;
  for (std::size_t i = 0; i < run.messages.size(); ++i) {
    ++counts[run.sensors[i]];
    ASSERT_TRUE(std::visit([](const auto& m) { return msgs::validate(m); }, run.messages[i])) << run.sensors[i];
    if (i > 0) {
      ASSERT_LE(msgs::timestamp_of(run.messages[i - 1]), msgs::timestamp_of(run.messages[i])) << i;
    }
  }
  EXPECT_EQ(counts["imu"], 201);     // 0 .. 1 s inclusive at 200 Hz
  EXPECT_EQ(counts["wheels"], 51);
  EXPECT_EQ(counts["gnss"], 6);
  EXPECT_EQ(counts["radar"], 21);
  EXPECT_EQ(counts["lidar"], 10);    // sweeps that finish by 1 s
  EXPECT_EQ(counts["camera_front"], 11);
}

TEST(ScenarioSimulation, SameSeedSameMessagesOtherSeedOtherNoise) {
  Result<Scenario> scenario = load_scenario("examples/scenarios/warehouse_robot.yaml");
  ASSERT_TRUE(scenario);
  std::get<CameraSimulatorConfig>(scenario->sensors[2].simulator).intrinsics = {100.0, 100.0, 79.5, 59.5, 160, 120};
  const RecordedRun first = record(*scenario, 0.5);
  scenario->num_threads = 2;  // the thread count never changes the output
  const RecordedRun second = record(*scenario, 0.5);
  ASSERT_EQ(first.messages.size(), second.messages.size());
  for (std::size_t i = 0; i < first.messages.size(); ++i) {
    if (const auto* imu = std::get_if<msgs::ImuMessage>(&first.messages[i])) {
      EXPECT_EQ(imu->linear_acceleration, std::get<msgs::ImuMessage>(second.messages[i]).linear_acceleration);
    } else if (const auto* cloud = std::get_if<msgs::PointCloudMessage>(&first.messages[i])) {
      EXPECT_EQ(cloud->points, std::get<msgs::PointCloudMessage>(second.messages[i]).points);
    } else if (const auto* image = std::get_if<msgs::ImageMessage>(&first.messages[i])) {
      EXPECT_EQ(image->data, std::get<msgs::ImageMessage>(second.messages[i]).data);
    }
  }
  set_seed(*scenario, 99);
  const RecordedRun reseeded = record(*scenario, 0.5);
  EXPECT_NE(std::get<msgs::ImuMessage>(reseeded.messages[0]).linear_acceleration,
            std::get<msgs::ImuMessage>(first.messages[0]).linear_acceleration);
}

const char* kMinimal = R"(scenario:
  name: minimal
  trajectory:
    type: ground_vehicle
    waypoints: [[0, 0], [10, 0]]
  sensors:
    imu: {rate: 100}
)";

std::string with(const std::string& line) { return std::string(kMinimal) + line; }

TEST(Scenario, BadFilesFailNamingLineAndKey) {
  ASSERT_TRUE(parse_scenario(kMinimal, "s.yaml"));
  struct Case {
    std::string text;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {with("    lidar: {model: livox}\n"), "s.yaml:8: sensors.lidar.model: unknown LiDAR 'livox'"},
      {with("    lidar: {horizontal_fov_deg: 400}\n"), "sensors.lidar.horizontal_fov_deg: 400 degrees: at most 360"},
      {with("    thermometer: {rate: 1}\n"), "sensors.thermometer: cannot tell the sensor's modality"},
      {with("    imu2: {rate: -5}\n"), "sensors.imu2.rate: expected a positive number, got -5"},
      {with("    camera: {width: 640.5}\n"), "sensors.camera.width: expected an integer, got '640.5'"},
      {with("  seed: -2\n"), "seed: expected a whole number in 0.."},
      {with("    gnss: {to_body: {rotation: [1, 1, 0, 0]}}\n"), "sensors.gnss.to_body.rotation: not a unit quaternion"},
      {with("  faults:\n    - {type: rain, start: 1, end: 2}\n"), "faults[0]: no lidar sensor in the scenario"},
      {with("  faults:\n    - {type: earthquake, start: 1, end: 2}\n"), "faults[0].type: unknown fault 'earthquake'"},
      {with("  faults:\n    - {type: gnss_outage, start: 5, end: 2}\n"), "faults[0].end: a fault must end after it starts"},
      {with("  colour: blue\n"), "unknown key"},
      {std::string(kMinimal).replace(std::string(kMinimal).find("[[0, 0], [10, 0]]"), 17, "[[0, 0], [0, 0]]"),
       "waypoints[1]: same x, y"},
      {with("  world: {boxes: [{center: [1, 2, 3], size: [1, 0, 1]}]}\n"), "world.boxes[0].size: sizes must be > 0"},
      {"scenario:\n  name: s\n  trajectory:\n    type: stations\n    stations: [[0, 0, 1, 0, 0]]\n  sensors:\n    imu: {rate: 100}\n",
       "s.yaml:5: trajectory.stations[0]: expected 6 numbers (x, y, z, roll, pitch, yaw; m, degrees), got 5"},
  };
  for (const Case& c : cases) {
    const Result<Scenario> scenario = parse_scenario(c.text, "s.yaml");
    if (scenario) {
      // Trajectory errors surface when the trajectory is built.
      const Result<SplineTrajectory> trajectory = make_trajectory(*scenario);
      ASSERT_FALSE(trajectory) << c.expected;
      EXPECT_THAT(trajectory.error().message, HasSubstr(c.expected));
      continue;
    }
    EXPECT_THAT(scenario.error().message, HasSubstr(c.expected));
  }
}

}  // namespace
}  // namespace hanzo::fusion::sim
