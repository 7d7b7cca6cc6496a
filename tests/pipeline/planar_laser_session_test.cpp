// The Session with a 2D laser scanner (`type: planar_laser`): real scans of the Intel Research
// Lab (CARMEN log) with drifting wheel odometry, and the simulated warehouse drive with a
// planar laser in place of its VLP-16, with and without an IMU.

#include <cmath>
#include <cstdio>
#include <set>

#include <gtest/gtest.h>

#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/io/carmen_import.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/lidar_simulator.hpp"
#include "hanzo/fusion/sim/planar_odometry_error.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "pipeline/scenario_replay.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using config::SensorModality;

double aligned_rmse(const io::Trajectory& truth, const io::Trajectory& estimate) {
  const auto ape = eval::compute_ape(truth, estimate, {.relation = eval::PoseRelation::kTranslation, .alignment = eval::Alignment::kSE3});
  EXPECT_TRUE(ape.ok()) << (ape.ok() ? "" : ape.error().message);
  return ape ? ape->statistics.rmse : 1e9;
}

config::SensorConfig sensor(const std::string& name, SensorModality modality, double rate, const std::string& type = "") {
  config::SensorConfig entry;
  entry.name = name;
  entry.modality = modality;
  entry.topic = "/" + name;
  entry.rate_hz = rate;
  entry.type = type;
  entry.body_frame = name + "_link";
  return entry;
}

// Intel lab: the scans as logged (about one every 3 s: the corrected log keeps keyframes, and
// some lie 0.18 s apart with a 0.5 rad turn between them), wheel odometry at 20 Hz along the
// logged (corrected) poses made 5 % too long with 0.5 deg/m of heading drift. Without an IMU the
// planar SLAM's odometry is the wheels' dead reckoning: the session's optimized trajectory lands
// near what `slam2d` reaches on the same data (0.07 m).
TEST(PlanarLaserSession, IntelLabScansCorrectDriftingWheels) {
  const io::CarmenLog log = io::read_carmen(std::string(HANZO_DATA_DIR) + "/laser2d_carmen/intel-corrected.log.gz", {}).value();
  std::vector<SE2> logged;
  for (const io::PoseMatrix& pose : log.report.scan_poses.poses) logged.push_back(io::planar_pose(pose));
  const std::vector<SE2> odometry = sim::corrupt_planar_odometry(logged, {.scale_error = 0.05, .heading_drift_per_meter = 0.5 * M_PI / 180.0});

  config::FusionConfig fusion;
  fusion.frontend.planar = true;
  fusion.sensors = {sensor("laser", SensorModality::kLidar, 0.3, std::string(config::kPlanarLaserType)),
                    sensor("wheels", SensorModality::kWheelOdometry, 20.0)};
  fusion.sensors[1].fusion.use_yaw_rate = true;
  auto created = Session::create(fusion, calib::Calibration{});
  ASSERT_TRUE(created.ok()) << created.error().message;
  auto session = std::move(created).value();
  // Wheels at 20 Hz along the drifting odometry (interpolated between the scans' poses).
  constexpr double kSeparation = 0.5;
  double left = 0.0, right = 0.0;
  SE2 previous = odometry.front();
  io::Trajectory odometry_trajectory;
  for (std::size_t i = 0; i < log.scans.size(); ++i) {
    if (i > 0) {
      const Timestamp from = log.scans[i - 1].timestamp, to = log.scans[i].timestamp;
      const int steps = std::max(1, static_cast<int>(std::ceil((to - from).seconds() * 20.0)));
      for (int k = 1; k <= steps; ++k) {
        const SE2 pose = SE2::interpolate(odometry[i - 1], odometry[i], static_cast<double>(k) / steps);
        const SE2 step = previous.inverse() * pose;
        previous = pose;
        const double distance = step.translation().x() < 0 ? -step.translation().norm() : step.translation().norm();
        left += distance - step.angle() * kSeparation / 2;
        right += distance + step.angle() * kSeparation / 2;
        msgs::WheelOdometryMessage wheels;
        wheels.timestamp = from + Duration::from_seconds((to - from).seconds() * k / steps) - Duration::from_milliseconds(1);
        wheels.left_distance = left;
        wheels.right_distance = right;
        wheels.wheel_separation = kSeparation;
        (void)session->push("wheels", wheels);
      }
    }
    (void)session->push("laser", log.scans[i]);

    odometry_trajectory.timestamps.push_back(log.scans[i].timestamp);
    odometry_trajectory.poses.push_back(io::pose_matrix(odometry[i]));
  }
  session->flush();
  io::Trajectory optimized;
  for (const StampedPose& pose : session->optimized_trajectory()) {
    optimized.timestamps.push_back(pose.timestamp);
    optimized.poses.push_back(pose.T_world_body.matrix());
  }
  const MappingSummary mapping = session->mapping_summary();
  const double odometry_error = aligned_rmse(log.report.scan_poses, odometry_trajectory);
  const double slam_error = aligned_rmse(log.report.scan_poses, optimized);
  std::printf("Intel lab, %zu scans: aligned APE odometry %.3f m -> session %.3f m; %llu keyframes, %llu loop closures\n",
              log.scans.size(), odometry_error, slam_error, static_cast<unsigned long long>(mapping.map_keyframes),
              static_cast<unsigned long long>(mapping.loop_closures));
  EXPECT_GT(odometry_error, 1.0);
  EXPECT_LT(slam_error, 0.15);
  EXPECT_GT(mapping.loop_closures, 300U);
  EXPECT_GT(mapping.scans_registered, log.scans.size() * 95 / 100);
  const msgs::FusionMap map = session->map();
  ASSERT_TRUE(map.occupancy.has_value());
  const std::size_t free = static_cast<std::size_t>(std::count_if(map.occupancy->occupancy.begin(), map.occupancy->occupancy.end(),
                                                                   [](float p) { return p < maps::OccupancyConfig{}.free_threshold; }));
  EXPECT_GT(free, 20000U);  // 0.1 m cells of a 30 x 30 m lab
}

// The warehouse drive with a planar laser at 20 Hz (deskewed with the filter's motion):
// IMU + laser + wheels track in real time and the slipping wheels are caught; without an IMU the
// optimized trajectory is as good.
TEST(PlanarLaserSession, SimulatedWarehouseWithAndWithoutAnImu) {
  for (const std::set<SensorModality>& modalities :
       {std::set{SensorModality::kImu, SensorModality::kLidar, SensorModality::kWheelOdometry},
        std::set{SensorModality::kLidar, SensorModality::kWheelOdometry}}) {
    sim::Scenario scenario = sim::load_scenario("examples/scenarios/warehouse_robot.yaml").value();
    std::erase_if(scenario.sensors, [&](const sim::ScenarioSensor& s) { return modalities.count(s.modality) == 0; });
    for (sim::ScenarioSensor& entry : scenario.sensors) {
      if (entry.modality != SensorModality::kLidar) continue;
      auto& lidar = std::get<sim::LidarSimulatorConfig>(entry.simulator);
      lidar.pattern = sim::LidarPattern::preset(sim::LidarModel::kPlanarLaser);
      lidar.rate_hz = 20.0;
    }
    scenario.duration = 45.0;
    scenario.num_threads = 0;
    auto simulation = sim::ScenarioSimulation::create(scenario).value();
    const config::FusionConfig fusion = sim::scenario_fusion_config(scenario);
    ASSERT_EQ(fusion.find_sensor("lidar")->type, config::kPlanarLaserType);
    auto session = Session::create(fusion, sim::scenario_calibration(scenario)).value();
    const testing::ReplayedTrajectories replayed = testing::replay(*simulation, *session);
    const io::Trajectory& estimate = replayed.estimate;
    const io::Trajectory& truth = replayed.truth;
    const testing::ReplayedTrajectories optimized_run = testing::optimized_with_truth(*session, *simulation);
    const io::Trajectory& optimized = optimized_run.estimate;
    const io::Trajectory& optimized_truth = optimized_run.truth;
    const bool imu = modalities.count(SensorModality::kImu) != 0;
    const double real_time = aligned_rmse(truth, estimate), smoothed = aligned_rmse(optimized_truth, optimized);
    const MappingSummary mapping = session->mapping_summary();
    std::printf("warehouse 45 s, planar laser%s: SE3-aligned APE real time %.3f m, optimized %.3f m; %llu of %llu scans matched, %llu slip episodes\n",
                imu ? " + IMU + wheels" : " + wheels", real_time, smoothed, static_cast<unsigned long long>(mapping.scans_registered),
                static_cast<unsigned long long>(mapping.scans_received), static_cast<unsigned long long>(mapping.wheel_slip_episodes));
    EXPECT_GT(mapping.scans_registered, mapping.scans_received * 95 / 100);
    EXPECT_LT(smoothed, 0.05);
    if (imu) {
      EXPECT_LT(real_time, 0.1);
      EXPECT_EQ(mapping.wheel_slip_episodes, 1U);
    }
  }
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
