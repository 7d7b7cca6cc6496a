// The ablation through the Session as `run` drives it; bench/ablation.sh runs the full table on
// every shipped scenario.
//  - The outage drive (examples/scenarios/gnss_outage_vehicle.yaml: IMU, wheels, RTK-float GNSS
//    with a 30 s outage): every sensor together is more accurate than the IMU with any single
//    aiding sensor and than the set without the IMU, in real time and optimized (world-frame
//    APE, no alignment).
//  - The urban drive (urban_vehicle.yaml: OS1-64 LiDAR, GNSS through a canyon with multipath, an
//    outage and rain on the LiDAR, wheels, radar): every sensor together has the best real-time
//    error in a level world (yaw-aligned APE: the IMU measures gravity, so roll and pitch count)
//    of the IMU + one sensor runs and the best world-frame APE of the runs that have a world frame
//    (GNSS); while GNSS is degraded or lost and rain blinds the LiDAR (20-63 s) its error stays
//    within 2x of its error over the whole drive. Its SE3-aligned shape is not the best: with GNSS
//    the LiDAR map's frame moves onto the GNSS world as the fixes come (RTK float, errors
//    correlated over seconds), while IMU + LiDAR keep the start's frame, tilt included. The
//    optimized trajectory (the GNSS error estimated in the graph) has the best world error and a
//    shape within 0.1 m.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <set>

#include <gtest/gtest.h>

#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "pipeline/scenario_replay.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using config::SensorModality;

double ape_rmse(const testing::ReplayedTrajectories& run) {
  const auto ape = eval::compute_ape(run.truth, run.estimate, {.relation = eval::PoseRelation::kTranslation, .alignment = eval::Alignment::kNone});
  EXPECT_TRUE(ape.ok()) << (ape.ok() ? "" : ape.error().message);
  return ape ? ape->statistics.rmse : 1e9;
}

TEST(Ablation, EverySensorTogetherBeatsEverySubsetOnTheOutageDrive) {
  const sim::Scenario full = sim::load_scenario("examples/scenarios/gnss_outage_vehicle.yaml").value();
  const std::set<SensorModality> all{SensorModality::kImu, SensorModality::kGnss, SensorModality::kWheelOdometry};
  std::map<std::string, std::pair<double, double>> errors;  // subset -> (real time, optimized)
  for (const std::set<SensorModality>& modalities :
       {all, std::set{SensorModality::kImu, SensorModality::kGnss}, std::set{SensorModality::kImu, SensorModality::kWheelOdometry},
        std::set{SensorModality::kGnss, SensorModality::kWheelOdometry}}) {
    sim::Scenario scenario = full;
    std::erase_if(scenario.sensors, [&](const sim::ScenarioSensor& s) { return modalities.count(s.modality) == 0; });
    auto simulation = sim::ScenarioSimulation::create(scenario).value();
    auto session = Session::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario)).value();
    const testing::ReplayedTrajectories real_time = testing::replay(*simulation, *session);
    const testing::ReplayedTrajectories optimized = testing::optimized_with_truth(*session, *simulation);
    std::string name;
    for (const sim::ScenarioSensor& sensor : scenario.sensors) name += (name.empty() ? "" : "+") + sensor.name;
    errors[name] = {ape_rmse(real_time), ape_rmse(optimized)};
    std::printf("outage drive, %-16s APE real time %7.3f m, optimized %7.3f m\n", name.c_str(), errors[name].first, errors[name].second);
  }
  const auto& [all_real_time, all_optimized] = errors.at("imu+gnss+wheels");
  for (const auto& [name, error] : errors) {
    if (name == "imu+gnss+wheels") continue;
    EXPECT_LT(all_real_time, error.first) << name;
    EXPECT_LT(all_optimized, error.second) << name;
  }
  EXPECT_LT(all_optimized, 0.6);
}

TEST(Ablation, EverySensorTogetherHasTheBestLevelAndWorldErrorOnTheUrbanDrive) {
  const sim::Scenario full = sim::load_scenario("examples/scenarios/urban_vehicle.yaml").value();
  const std::set<SensorModality> all{SensorModality::kImu, SensorModality::kLidar, SensorModality::kGnss, SensorModality::kWheelOdometry,
                                     SensorModality::kRadar};
  struct Errors {
    double world = 0.0;      // m, real time, no alignment
    double level = 0.0;      // m, real time, yaw-aligned
    double shape = 0.0;      // m, real time, SE3-aligned
    double degraded = 0.0;   // m, real time, no alignment, 20-63 s
    double optimized_world = 0.0;  // m, optimized, no alignment
    double optimized_shape = 0.0;  // m, optimized, SE3-aligned
  };
  std::map<std::string, Errors> errors;
  for (const SensorModality aiding : {SensorModality::kLidar, SensorModality::kGnss, SensorModality::kWheelOdometry, SensorModality::kRadar,
                                      SensorModality::kImu}) {
    // kImu stands for "every sensor".
    const std::set<SensorModality> modalities = aiding == SensorModality::kImu ? all : std::set{SensorModality::kImu, aiding};
    sim::Scenario scenario = full;
    std::erase_if(scenario.sensors, [&](const sim::ScenarioSensor& s) { return modalities.count(s.modality) == 0; });
    scenario.num_threads = 0;
    auto simulation = sim::ScenarioSimulation::create(scenario).value();
    auto session = Session::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario)).value();
    const testing::ReplayedTrajectories real_time = testing::replay(*simulation, *session);
    const auto shape = eval::compute_ape(real_time.truth, real_time.estimate, {.relation = eval::PoseRelation::kTranslation,
                                                                               .alignment = eval::Alignment::kSE3});
    ASSERT_TRUE(shape.ok());
    const auto level = eval::compute_ape(real_time.truth, real_time.estimate, {.relation = eval::PoseRelation::kTranslation,
                                                                               .alignment = eval::Alignment::kYaw});
    ASSERT_TRUE(level.ok());
    const std::string name = aiding == SensorModality::kImu ? "all" : "imu+" + std::string(config::to_string(aiding));
    double squared_sum = 0.0;
    int count = 0;
    for (size_t i = 0; i < real_time.estimate.size(); ++i) {
      const double t = (real_time.estimate.timestamps[i] - scenario.start_time).seconds();
      if (t < 20.0 || t > 63.0) continue;
      squared_sum += (real_time.estimate.poses[i].block<3, 1>(0, 3) - real_time.truth.poses[i].block<3, 1>(0, 3)).squaredNorm();
      ++count;
    }
    const testing::ReplayedTrajectories optimized = testing::optimized_with_truth(*session, *simulation);
    const auto optimized_shape = eval::compute_ape(optimized.truth, optimized.estimate, {.relation = eval::PoseRelation::kTranslation,
                                                                                         .alignment = eval::Alignment::kSE3});
    ASSERT_TRUE(optimized_shape.ok());
    errors[name] = {ape_rmse(real_time), level->statistics.rmse, shape->statistics.rmse, std::sqrt(squared_sum / std::max(count, 1)),
                    ape_rmse(optimized), optimized_shape->statistics.rmse};
    std::printf("urban drive, %-19s APE real time %7.3f m (%7.3f m while degraded), yaw-aligned %7.3f m, SE3-aligned %7.3f m; "
                "optimized %7.3f m, SE3-aligned %7.3f m\n",
                name.c_str(), errors[name].world, errors[name].degraded, errors[name].level, errors[name].shape, errors[name].optimized_world,
                errors[name].optimized_shape);
  }
  const Errors& every = errors.at("all");
  for (const auto& [name, error] : errors) {
    if (name == "all") continue;
    EXPECT_LT(every.level, error.level) << name;
  }
  // Measured with the Frontend following the graph that holds the fixes (frontend_follows_graph):
  // world 0.43 m (0.52 m with the filter fusing the fixes, 1.28 m with the LiDAR map fixed at the
  // start), yaw-aligned 0.40 m (IMU + LiDAR 0.76 m), SE3-aligned 0.39 m (IMU + LiDAR 0.06 m).
  EXPECT_LT(every.world, errors.at("imu+gnss").world);
  EXPECT_LT(every.world, 0.5);
  EXPECT_LT(every.shape, 0.5);
  EXPECT_LT(every.degraded, 2.0 * every.world);
  // The graph with the GNSS error estimated (keyframe_graph.hpp): measured optimized world 0.15 m
  // (IMU + GNSS 13.3 m; 0.17 m with the filter fusing the fixes, 0.37 m with the fixes
  // independent), SE3-aligned 0.036 m (0.051 m, 0.24 m).
  EXPECT_LT(every.optimized_world, errors.at("imu+gnss").optimized_world);
  EXPECT_LT(every.optimized_world, 0.2);
  EXPECT_LT(every.optimized_shape, 0.06);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline

namespace hanzo::fusion::pipeline {
namespace {

// examples/scenarios/delivery_van.yaml with every sensor (IMU, OS1-64, GNSS with a 25 s outage
// indoors, rain on the LiDAR, wheels, radar): the optimized trajectory within the issue's
// 0.15 m SE3-aligned (measured 0.091 m with the Frontend following the graph; 0.100 m with the
// filter fusing the fixes, 0.198 m with the fixes independent) and 0.25 m in the world frame
// (0.124 m; 0.142 m, 0.272 m).
TEST(Ablation, TheDeliveryVanWithEverySensorIsOptimizedWithin15Centimetres) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/delivery_van.yaml").value();
  scenario.num_threads = 0;
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  auto session = Session::create(sim::scenario_fusion_config(scenario), sim::scenario_calibration(scenario)).value();
  testing::replay(*simulation, *session);
  const testing::ReplayedTrajectories optimized = testing::optimized_with_truth(*session, *simulation);
  const auto shape = eval::compute_ape(optimized.truth, optimized.estimate, {.relation = eval::PoseRelation::kTranslation,
                                                                             .alignment = eval::Alignment::kSE3});
  ASSERT_TRUE(shape.ok());
  std::printf("delivery van, every sensor: optimized APE %.3f m, SE3-aligned %.3f m\n", ape_rmse(optimized), shape->statistics.rmse);
  EXPECT_LT(shape->statistics.rmse, 0.15);
  EXPECT_LT(ape_rmse(optimized), 0.25);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
