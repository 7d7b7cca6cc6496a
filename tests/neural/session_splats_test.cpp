// Gaussian splats trained inside a Session (fusion.mapping.splats, src/pipeline/session_splats.hpp)
// on the simulated warehouse (IMU + VLP-16 + front camera): the map carries them, they reproduce
// camera images the training never saw at the session's own optimized poses, replay gives the
// same Gaussians bit for bit, and a realtime session trains them in the background.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>

#include "hanzo/fusion/maps/splat_ply.hpp"
#include "hanzo/fusion/neural/log_views.hpp"
#include "hanzo/fusion/neural/map_layers.hpp"
#include "hanzo/fusion/neural/splat_trainer.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"

namespace hanzo::fusion {
namespace {

using pipeline::Session;
using pipeline::SessionConfig;
using pipeline::SessionMode;

struct SplatRun {
  std::unique_ptr<Session> session;
  std::vector<msgs::ImageMessage> images;  // every camera image of the log
  sim::ScenarioSensor camera;
  calib::Calibration calibration;
};

SplatRun run_warehouse(SessionMode mode, double duration, bool lidar = true) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/warehouse_robot.yaml").value();
  std::erase_if(scenario.sensors, [&](const sim::ScenarioSensor& s) {
    return s.modality != config::SensorModality::kImu && (s.modality != config::SensorModality::kLidar || !lidar) &&
           s.modality != config::SensorModality::kCamera;
  });
  scenario.duration = duration;
  scenario.num_threads = 0;
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  config::FusionConfig fusion = sim::scenario_fusion_config(scenario);
  fusion.mapping.splats.enabled = true;
  fusion.mapping.splats.image_width = 80;  // 640 x 480 / 8: a short test
  SplatRun run;
  run.calibration = sim::scenario_calibration(scenario);
  SessionConfig session_config = SessionConfig::from(fusion);
  session_config.mode = mode;
  run.session = Session::create(fusion, run.calibration, session_config).value();
  const Status status = simulation->run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status {
    if (const auto* image = std::get_if<msgs::ImageMessage>(&message)) {
      run.images.push_back(*image);
      run.camera = sensor;
    }
    (void)run.session->push(sensor.name, std::move(message));  // refusals are the Session's to count
    return ok_status();
  });
  EXPECT_TRUE(status.ok());
  run.session->flush();
  return run;
}

/// The images halfway between two kept views' times (every 10th image, offset by 5), at the
/// session's optimized poses.
std::vector<neural::PosedView> held_out_views(const SplatRun& run) {
  const std::vector<pipeline::StampedPose> trajectory = run.session->optimized_trajectory();
  const calib::SensorCalibration& camera = *run.calibration.find(run.camera.name);
  std::vector<neural::PosedView> views;
  for (std::size_t i = 5; i < run.images.size(); i += 10) {
    const msgs::ImageMessage& image = run.images[i];
    const Timestamp time = image.timestamp + camera.time_offset;
    const auto after = std::lower_bound(trajectory.begin(), trajectory.end(), time, [](const pipeline::StampedPose& pose, Timestamp t) { return pose.timestamp < t; });
    if (after == trajectory.begin() || after == trajectory.end()) continue;
    const auto before = after - 1;
    const double share = (time - before->timestamp).seconds() / (after->timestamp - before->timestamp).seconds();
    const SE3 T_world_camera = SE3::interpolate(before->T_world_body, after->T_world_body, share) * camera.T_body_sensor();
    auto view = neural::image_view(image, camera.camera->intrinsics, camera.camera->distortion, T_world_camera, 8);
    EXPECT_TRUE(view.ok());
    if (view) views.push_back(std::move(view).value());
  }
  return views;
}

TEST(SessionSplats, ReplayTrainsSplatsThatRenderHeldOutImagesAndRepeatsExactly) {
  const SplatRun run = run_warehouse(SessionMode::kReplay, 16.0);
  const pipeline::MappingSummary mapping = run.session->mapping_summary();
  const msgs::FusionMap map = run.session->map();
  ASSERT_TRUE(map.gaussian_splats.has_value());
  EXPECT_GT(mapping.splat_views, 15U);
  // steps_per_view (10) after each view, once the first map points seeded Gaussians.
  EXPECT_LE(mapping.splat_iterations, mapping.splat_views * 10);
  EXPECT_GE(mapping.splat_iterations, (mapping.splat_views - 5) * 10);
  EXPECT_EQ(mapping.splat_gaussians, map.gaussian_splats->opacity_logits.size());
  EXPECT_EQ(map.gaussian_splats->provenance.iterations, mapping.splat_iterations);
  const neural::GaussianCloud cloud = neural::from_splat_layer(*map.gaussian_splats).value();

  const std::vector<neural::PosedView> views = held_out_views(run);
  ASSERT_GT(views.size(), 10U);
  neural::RasterizerConfig render;
  render.active_sh_degree = 1;
  const neural::EvaluationSummary score = neural::evaluate_splats(cloud, views, render);
  std::printf("session splats, warehouse 16 s: %llu views, %llu steps, %zu Gaussians; %zu held-out images at the optimized poses: PSNR %.2f dB, "
              "SSIM %.3f\n",
              static_cast<unsigned long long>(mapping.splat_views), static_cast<unsigned long long>(mapping.splat_iterations), cloud.size(), views.size(),
              score.mean_psnr, score.mean_ssim);
  EXPECT_GT(score.mean_psnr, 22.0);  // 24.3 dB measured
  EXPECT_GT(score.mean_ssim, 0.75);

  // Deterministic: the same log gives the same Gaussians.
  const SplatRun again = run_warehouse(SessionMode::kReplay, 16.0);
  const msgs::FusionMap again_map = again.session->map();
  ASSERT_TRUE(again_map.gaussian_splats.has_value());
  EXPECT_EQ(again_map.gaussian_splats->positions, map.gaussian_splats->positions);
  EXPECT_EQ(again_map.gaussian_splats->sh, map.gaussian_splats->sh);
  EXPECT_EQ(again_map.gaussian_splats->opacity_logits, map.gaussian_splats->opacity_logits);

  // The layer as a 3DGS viewer's PLY and back, exactly.
  const msgs::GaussianSplatLayer read = maps::decode_splat_ply(maps::encode_splat_ply(*map.gaussian_splats), "test").value();
  EXPECT_EQ(read.positions, map.gaussian_splats->positions);
  EXPECT_EQ(read.sh, map.gaussian_splats->sh);
  EXPECT_EQ(read.rotations, map.gaussian_splats->rotations);
}

TEST(SessionSplats, RealtimeSessionTrainsInTheBackground) {
  const SplatRun run = run_warehouse(SessionMode::kRealtime, 8.0);
  EXPECT_GT(run.session->mapping_summary().splat_views, 5U);
  // The worker trains on after the log ended; wait for its steps (not for a time).
  for (int wait = 0; wait < 600 && run.session->mapping_summary().splat_iterations < 50; ++wait) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const pipeline::MappingSummary mapping = run.session->mapping_summary();
  EXPECT_GE(mapping.splat_iterations, 50U);
  const msgs::FusionMap map = run.session->map();
  ASSERT_TRUE(map.gaussian_splats.has_value());
  EXPECT_GT(map.gaussian_splats->opacity_logits.size(), 1000U);
  EXPECT_GT(map.gaussian_splats->provenance.training_seconds, 0.0);
}

// Without a LiDAR no map points seed them: each view starts Gaussians at random depths in front
// of it, and the training still reproduces the images.
TEST(SessionSplats, WithoutALidarGaussiansStartInFrontOfEachView) {
  const SplatRun run = run_warehouse(SessionMode::kReplay, 8.0, /*lidar=*/false);
  const pipeline::MappingSummary mapping = run.session->mapping_summary();
  EXPECT_GT(mapping.splat_views, 5U);
  EXPECT_GE(mapping.splat_iterations, (mapping.splat_views - 1) * 10);  // every view seeds Gaussians
  const msgs::FusionMap map = run.session->map();
  ASSERT_TRUE(map.gaussian_splats.has_value());
  EXPECT_GE(map.gaussian_splats->opacity_logits.size(), 500U);
}

TEST(SessionSplats, NeedACamera) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/warehouse_robot.yaml").value();
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& s) { return s.modality == config::SensorModality::kCamera; });
  config::FusionConfig fusion = sim::scenario_fusion_config(scenario);
  fusion.mapping.splats.enabled = true;
  const auto refused = Session::create(fusion, sim::scenario_calibration(scenario));
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("no camera with intrinsics"), std::string::npos) << refused.error().message;
}

}  // namespace
}  // namespace hanzo::fusion
