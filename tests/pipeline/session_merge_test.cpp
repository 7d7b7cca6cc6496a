// Sessions joined into one keyframe graph (pipeline/session_merge.hpp): two sessions of the
// simulated warehouse that start at different places, facing different ways, and drive the same
// aisles in opposite directions (their frames a quarter turn apart, no guess given). Inter-session
// loops join them; every keyframe of the merged map lies within 0.10 m of the truth, and the map
// survives its file. A session whose only shared place is its start, in a warehouse symmetric
// under a half turn, is refused as ambiguous; scans of another place (a room of pillars) are
// refused with the reason.

#include <cmath>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/eval/alignment.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/pipeline/session_merge.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "scenario_replay.hpp"

namespace hanzo::fusion::pipeline {
namespace {

struct SessionRun {
  msgs::FusionMap map;
  std::vector<Eigen::Vector3d> keyframe_truth;  ///< the LiDAR's true position at each keyframe
};

SessionRun patrol(const std::string& name, uint64_t seed, std::vector<Eigen::Vector3d> waypoints) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/warehouse_robot.yaml").value();
  scenario.duration = 30.0;
  scenario.num_threads = 0;
  scenario.ground_path.waypoints = std::move(waypoints);
  sim::set_seed(scenario, seed);
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& sensor) { return sensor.name != "imu" && sensor.name != "lidar" && sensor.name != "wheels"; });
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  const calib::Calibration calibration = sim::scenario_calibration(scenario);
  auto session = Session::create(sim::scenario_fusion_config(scenario), calibration).value();
  (void)testing::replay(*simulation, *session);
  SessionRun run{session->map(), {}};
  run.map.map_id = name;
  const SE3 T_body_lidar = calibration.find("lidar")->T_body_sensor();
  for (const msgs::LidarKeyframe& keyframe : run.map.lidar_keyframes.value().keyframes) {
    run.keyframe_truth.push_back((simulation->trajectory().sample(keyframe.time).T_world_body * T_body_lidar).translation());
  }
  return run;
}

/// Keyframes of a room with pillars on a grid, walls 2.5 m high: no place of the warehouse.
msgs::FusionMap pillar_room() {
  std::vector<Eigen::Vector3f> room;
  std::mt19937 random(7);
  std::uniform_real_distribution<float> noise(-0.02F, 0.02F);
  for (float x = -15.0F; x <= 15.0F; x += 0.1F) {
    for (float y = -15.0F; y <= 15.0F; y += 0.1F) {
      room.emplace_back(x, y, noise(random));
      const bool wall = std::abs(x) > 14.95F || std::abs(y) > 14.95F;
      const bool pillar = std::hypot(std::fmod(x + 15.0F, 6.0F) - 3.0F, std::fmod(y + 15.0F, 4.5F) - 2.25F) < 0.3F;
      if (wall || pillar) {
        for (float z = 0.1F; z <= 2.5F; z += 0.1F) room.emplace_back(x, y, z + noise(random));
      }
    }
  }
  msgs::FusionMap map;
  map.map_id = "pillars";
  map.lidar_keyframes.emplace();
  for (int k = 0; k < 30; ++k) {
    const SE3 T_world_lidar(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 0.1 * k), Eigen::Vector3d(-10.0 + 0.7 * k, 0.5, 0.5));
    msgs::LidarKeyframe keyframe{Timestamp::from_nanoseconds(1'000'000'000LL * (k + 1)), msgs::Pose::from_se3(T_world_lidar), {}, 0};
    for (const Eigen::Vector3f& point : room) {
      const Eigen::Vector3d in_lidar = T_world_lidar.inverse() * point.cast<double>();
      if (in_lidar.norm() < 25.0 && (k % 2 == 0 || point.x() > 0.0F)) keyframe.points.push_back(in_lidar.cast<float>());
    }
    map.lidar_keyframes->keyframes.push_back(std::move(keyframe));
  }
  return map;
}

TEST(SessionMerge, TwoSessionsDrivingOppositeWaysJoinInOneGraphAndAmbiguousOrOtherPlacesAreRefused) {
  // East: along the south aisle, then north along the east side. West: south along the east
  // side, then west along the south aisle.
  const SessionRun a = patrol("east", 1, {{15, -1.5, 0.15}, {34, -1.5, 0.15}, {34, 14.5, 0.15}, {-3, 14.5, 0.15}, {-3, -1.5, 0.15}});
  const SessionRun b = patrol("west", 2, {{34, 8, 0.15}, {34, -1.5, 0.15}, {-3, -1.5, 0.15}, {-3, 14.5, 0.15}, {34, 14.5, 0.15}});
  SessionMergeConfig config;
  config.odometry.map.voxel_size = 0.5;  // indoors (map merge --indoor)
  config.odometry.source_voxel_size = 0.25;
  const SessionMergeResult merged = merge_sessions({a.map, b.map}, config).value();
  ASSERT_EQ(merged.joins.size(), 1U);
  const double yaw = merged.joins[0].T_joined_map.rotation().log().z();
  std::printf("joined: %zu queries, %zu candidates, %zu verified, %zu loops; B at yaw %.2f deg; chi2 %.1f -> %.1f\n", merged.queries,
              merged.candidates, merged.verified, merged.inter_session_loops, yaw * 180 / std::numbers::pi, merged.initial_chi2, merged.final_chi2);
  EXPECT_GE(merged.inter_session_loops, config.min_agreeing_loops);
  EXPECT_NEAR(yaw, -std::numbers::pi / 2, 0.02) << "west starts facing south, east facing east";

  // Every keyframe of both sessions against the truth, one rigid alignment for all.
  const auto& keyframes = merged.merged.lidar_keyframes.value();
  ASSERT_EQ(keyframes.keyframes.size(), a.keyframe_truth.size() + b.keyframe_truth.size());
  EXPECT_EQ(keyframes.sources, (std::vector<std::string>{"east", "west"}));
  std::vector<Eigen::Vector3d> estimate, truth = a.keyframe_truth;
  truth.insert(truth.end(), b.keyframe_truth.begin(), b.keyframe_truth.end());
  for (const msgs::LidarKeyframe& keyframe : keyframes.keyframes) estimate.push_back(keyframe.T_world_lidar.position);
  const eval::SimilarityTransform alignment = eval::umeyama_alignment(estimate, truth, false).value();
  double worst = 0.0, sum = 0.0;
  for (std::size_t k = 0; k < estimate.size(); ++k) {
    const double error = (alignment.rotation * estimate[k] + alignment.translation - truth[k]).norm();
    worst = std::max(worst, error);
    sum += error;
    EXPECT_LT(error, 0.10) << "keyframe " << k << " of " << keyframes.sources[keyframes.keyframes[k].source];
  }
  std::printf("%zu keyframes: mean %.3f m, max %.3f m from the truth\n", estimate.size(), sum / static_cast<double>(estimate.size()), worst);
  ASSERT_TRUE(merged.merged.points && merged.merged.occupancy);

  const msgs::FusionMap reread = maps::parse_fusion_map(maps::serialize_fusion_map(merged.merged, {.chunk_bytes = 1 << 16}).value()).value();
  ASSERT_TRUE(reread.lidar_keyframes);
  EXPECT_EQ(reread.lidar_keyframes->sources, keyframes.sources);
  ASSERT_EQ(reread.lidar_keyframes->keyframes.size(), keyframes.keyframes.size());
  EXPECT_EQ(reread.lidar_keyframes->keyframes.back().points, keyframes.keyframes.back().points);
  EXPECT_EQ(reread.lidar_keyframes->keyframes.back().source, 1U);

  // The warehouse is symmetric under a half turn about its middle. A session that shares only
  // its start with east (from the same place, facing west, round the other way) sees the
  // shelves and pillars east saw from the other side: its loops agree on two places (the true
  // one at the start, the turned one along the side aisles), and the merge refuses it as
  // ambiguous instead of joining it by the larger set.
  const SessionRun mirror = patrol("mirror", 3, {{15, -1.5, 0.15}, {-3, -1.5, 0.15}, {-3, 14.5, 0.15}, {34, 14.5, 0.15}, {34, -1.5, 0.15}});
  const Result<SessionMergeResult> ambiguous = merge_sessions({a.map, mirror.map}, config);
  ASSERT_FALSE(ambiguous) << "joined with yaw " << ambiguous->joins[0].T_joined_map.rotation().log().z();
  std::printf("symmetric: %s\n", ambiguous.error().message.c_str());
  EXPECT_NE(ambiguous.error().message.find("ambiguous"), std::string::npos);

  const Result<SessionMergeResult> refused = merge_sessions({a.map, pillar_room()}, config);
  ASSERT_FALSE(refused);
  std::printf("another place: %s\n", refused.error().message.c_str());
  EXPECT_NE(refused.error().message.find("pillars not joined to east"), std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
