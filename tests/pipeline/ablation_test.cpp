// The ablation on the outage drive (examples/scenarios/gnss_outage_vehicle.yaml: IMU, wheels,
// RTK-float GNSS with a 30 s outage), through the Session as `run` drives it: every sensor
// together is more accurate than the IMU with any single aiding sensor and than the set without
// the IMU, in real time and optimized (world-frame APE, no alignment). bench/ablation.sh runs
// the full table on every shipped scenario.
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

}  // namespace
}  // namespace hanzo::fusion::pipeline
