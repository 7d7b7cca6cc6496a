// Visual loop closure (vision/visual_odometry.hpp, place recognition and the similarity pose
// graph): a simulated walk around an office that returns to where it started, with loop closure
// off and on, against the simulator's ground truth.

#include <cstdio>
#include <cstdlib>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>

#include "hanzo/fusion/core/logging.hpp"

#include "hanzo/fusion/calib/camera_calibration.hpp"
#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "hanzo/fusion/vision/visual_odometry.hpp"

namespace hanzo::fusion::vision {
namespace {

bool verbose() { return std::getenv("HANZO_TEST_VERBOSE") != nullptr; }

struct RenderedWalk {
  std::vector<std::pair<double, cv::Mat>> images;
  PinholeCamera camera;
  cv::Size size;
  io::Trajectory truth_camera;  // T_world_camera at every image time
};

// The camera of a scenario rendered once (both runs see the same images).
RenderedWalk render(const std::string& scenario_path, double duration) {
  sim::Scenario scenario = sim::load_scenario(scenario_path).value();
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& s) { return s.modality != config::SensorModality::kCamera; });
  scenario.sensors.resize(1);
  if (duration > 0.0) scenario.duration = duration;
  scenario.num_threads = 0;
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  const auto& camera_config = std::get<sim::CameraSimulatorConfig>(scenario.sensors[0].simulator);
  const SE3 T_body_camera = scenario.sensors[0].T_body_sensor;
  RenderedWalk walk;
  walk.camera = calib::CameraCalibration{camera_config.intrinsics, camera_config.distortion}.pinhole_camera();
  walk.size = {static_cast<int>(camera_config.intrinsics.width), static_cast<int>(camera_config.intrinsics.height)};
  EXPECT_TRUE(simulation->run([&](const sim::ScenarioSensor&, msgs::SensorMessage&& message) -> Status {
    const auto& image = std::get<msgs::ImageMessage>(message);
    const cv::Mat pixels(static_cast<int>(image.height), static_cast<int>(image.width), image.encoding == msgs::ImageEncoding::kMono8 ? CV_8UC1 : CV_8UC3,
                         const_cast<uint8_t*>(image.data.data()));
    walk.images.emplace_back(image.timestamp.seconds(), pixels.clone());
    return ok_status();
  }).ok());
  for (const auto& [time, image] : walk.images) {
    walk.truth_camera.timestamps.push_back(Timestamp::from_seconds(time));
    walk.truth_camera.poses.push_back((simulation->trajectory().sample(Timestamp::from_seconds(time)).T_world_body * T_body_camera).matrix());
  }
  return walk;
}

struct WalkResult {
  double ape_rmse = 0.0;
  double path = 0.0;
  VisualOdometrySummary summary;
};

WalkResult run_walk(const RenderedWalk& walk, const VisualOdometryConfig& config) {
  auto odometry = VisualOdometry::create(walk.camera, walk.size, config).value();
  for (const auto& [time, image] : walk.images) {
    Result<VisualOdometryFrame> frame = odometry->track(time, image);
    EXPECT_TRUE(frame) << frame.error().message;
    if (frame && verbose() && (frame->loop_closed || frame->state != TrackingState::kTracking)) {
      std::printf("%.2f %-12s %4d%s %s\n", time - walk.images.front().first, to_string(frame->state), frame->tracked_landmarks, frame->loop_closed ? " LOOP" : "",
                  frame->reason.c_str());
    }
  }
  io::Trajectory estimate, truth;
  for (const auto& [time, pose] : odometry->trajectory()) {
    for (std::size_t i = 0; i < walk.truth_camera.size(); ++i) {
      if (std::abs(walk.truth_camera.timestamps[i].seconds() - time) < 1e-6) {
        estimate.timestamps.push_back(Timestamp::from_seconds(time));
        estimate.poses.push_back(pose.matrix());
        truth.timestamps.push_back(walk.truth_camera.timestamps[i]);
        truth.poses.push_back(walk.truth_camera.poses[i]);
        break;
      }
    }
  }
  eval::ApeConfig ape_config;
  ape_config.alignment = eval::Alignment::kSim3;
  const eval::ApeResult ape = eval::compute_ape(truth, estimate, ape_config).value();
  if (verbose()) {
    for (std::size_t i = 0; i < truth.size(); i += 30) {
      std::printf("  %.1f error %.3f\n", truth.timestamps[i].seconds() - walk.images.front().first, ape.errors[i]);
    }
  }
  return {ape.statistics.rmse, truth.path_length(), odometry->summary()};
}

// examples/scenarios/ar_handheld.yaml: a phone carried once round an office (mono camera,
// 15 Hz, radtan), back where it started. The default vocabulary was trained on real images
// only (docs/vision.md), none of this simulated office.
TEST(VisualLoopClosure, SimulatedHandheldWalkRoundTheOfficeClosesItsLoop) {
  if (verbose()) {
    auto stderr_logger = std::make_shared<spdlog::logger>("test", std::make_shared<spdlog::sinks::stderr_sink_mt>());
    stderr_logger->set_level(spdlog::level::debug);
    set_logger(stderr_logger);
  }
  const RenderedWalk walk = render("examples/scenarios/ar_handheld.yaml", 0.0);
  ASSERT_GT(walk.images.size(), 300u);
  VisualOdometryConfig open_loop;
  open_loop.loop_closure = false;
  const WalkResult without = std::getenv("HANZO_TEST_SKIP_OPEN_LOOP") ? WalkResult{} : run_walk(walk, open_loop);
  const WalkResult with = run_walk(walk, VisualOdometryConfig{});
  std::printf("handheld walk, %.1f m, %zu frames: Sim3 APE %.3f m open loop, %.3f m with %d loop closures (%d candidates)\n", with.path, walk.images.size(),
              without.ape_rmse, with.ape_rmse, with.summary.loop_closures, with.summary.loop_candidates);
  EXPECT_FALSE(without.summary.loop_closure_enabled);
  EXPECT_TRUE(with.summary.loop_closure_enabled);
  EXPECT_GE(with.summary.loop_closures, 1);
  EXPECT_LE(with.ape_rmse, 0.5 * without.ape_rmse);
}

}  // namespace
}  // namespace hanzo::fusion::vision
