// VisualLoopDetector (vision/visual_loop_detector.hpp): the simulated drone's left camera over
// two figure eights (examples/scenarios/drone.yaml), places every 0.75 m or 15 degrees, posed by
// a drifting "odometry" (the truth moved by a growing error: 1 % of the distance in position,
// 0.05 degree per metre in yaw, pessimistic for a visual-inertial odometry). The loops it finds
// must be right: each T_place_current against the simulator's true relative pose.

#include <cstdio>

#include <optional>
#include <utility>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "hanzo/fusion/calib/camera_calibration.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "hanzo/fusion/vision/visual_loop_detector.hpp"

namespace hanzo::fusion::vision {
namespace {

constexpr double kDegree = M_PI / 180.0;

struct RenderedFlight {
  std::vector<cv::Mat> images;
  std::vector<SE3> T_world_camera;  // the truth at every image
  PinholeCamera camera;
};

RenderedFlight render_drone(double duration) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/drone.yaml").value();
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& s) { return s.name != "camera_left"; });
  scenario.duration = duration;
  scenario.num_threads = 0;
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  const auto& camera_config = std::get<sim::CameraSimulatorConfig>(scenario.sensors[0].simulator);
  RenderedFlight flight;
  flight.camera = calib::CameraCalibration{camera_config.intrinsics, camera_config.distortion}.pinhole_camera();
  EXPECT_TRUE(simulation->run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status {
    const auto& image = std::get<msgs::ImageMessage>(message);
    flight.images.push_back(cv::Mat(static_cast<int>(image.height), static_cast<int>(image.width), CV_8UC1, const_cast<uint8_t*>(image.data.data())).clone());
    flight.T_world_camera.push_back(simulation->trajectory().sample(image.timestamp).T_world_body * sensor.T_body_sensor);
    return ok_status();
  }).ok());
  return flight;
}

TEST(VisualLoopDetector, FindsTheDronesLoopsWithTheirTrueRelativePose) {
  const RenderedFlight flight = render_drone(34.0);
  ASSERT_GT(flight.images.size(), 300u);
  VisualLoopDetector detector = VisualLoopDetector::create(flight.camera).value();
  std::vector<std::size_t> place_image;  // image of each place kept
  std::optional<std::size_t> last_offered;
  double travelled = 0.0;
  SE3 drift;
  std::vector<std::pair<VisualLoop, std::size_t>> loops;  // with the image that closed it
  for (std::size_t i = 0; i < flight.images.size(); ++i) {
    if (i > 0) {
      const double step = (flight.T_world_camera[i].translation() - flight.T_world_camera[i - 1].translation()).norm();
      travelled += step;
      drift = SE3(SO3::exp(Eigen::Vector3d(0.0, 0.0, 0.05 * kDegree * step)), Eigen::Vector3d(0.01 * step, -0.005 * step, 0.0)) * drift;
    }
    if (last_offered) {
      const SE3 since = flight.T_world_camera[*last_offered].inverse() * flight.T_world_camera[i];
      if (since.translation().norm() < 0.75 && since.rotation().log().norm() < 15.0 * kDegree) continue;
    }
    const int places_before = detector.size();
    Result<std::optional<VisualLoop>> loop = detector.add(flight.images[i], drift * flight.T_world_camera[i]);
    ASSERT_TRUE(loop) << loop.error().message;
    last_offered = i;
    const bool kept = detector.size() > places_before;
    if (kept) place_image.push_back(i);
    if (*loop) {
      EXPECT_EQ((*loop)->current, kept ? places_before : -1);
      loops.emplace_back(**loop, i);
    }
  }
  std::printf("%d places (%d revisits not kept) over %.1f m, %d candidates checked, %zu loops\n", detector.size(), detector.covered_places(),
              travelled, detector.candidates_checked(), loops.size());
  EXPECT_GE(loops.size(), 3u);
  EXPECT_GT(detector.covered_places(), 0) << "the figure eights pass the same places again";
  for (const auto& [loop, image] : loops) {
    const SE3 truth = flight.T_world_camera[place_image[static_cast<std::size_t>(loop.place)]].inverse() * flight.T_world_camera[image];
    const SE3 error = truth.inverse() * loop.T_place_current;
    std::printf("  place %d -> %d: %d inliers of %d, %.3f m apart, error %.3f m %.3f deg\n", loop.place, loop.current, loop.inliers, loop.matches,
                truth.translation().norm(), error.translation().norm(), error.rotation().log().norm() / kDegree);
    // Within 3 sigma of the covariance the loop reports, and within 0.2 m and 1 degree.
    EXPECT_LT(error.translation().norm(), 3.0 * std::sqrt(loop.covariance(0, 0))) << loop.place << " -> " << loop.current;
    EXPECT_LT(error.rotation().log().norm(), 3.0 * std::sqrt(loop.covariance(3, 3))) << loop.place << " -> " << loop.current;
    EXPECT_LT(error.translation().norm(), 0.2);
    EXPECT_LT(error.rotation().log().norm(), 1.0 * kDegree);
    EXPECT_GE(loop.inliers, 40);
  }
}

TEST(VisualLoopDetector, RefusesBadInputAndConfiguration) {
  PinholeCamera camera;
  camera.fx = camera.fy = 400.0;
  VisualLoopDetectorConfig config;
  config.min_place_gap = 1;
  EXPECT_FALSE(VisualLoopDetector::create(camera, config));
  config = {};
  config.features.max_features = 0;
  EXPECT_FALSE(VisualLoopDetector::create(camera, config));
  camera.fx = 0.0;
  EXPECT_FALSE(VisualLoopDetector::create(camera));
  camera.fx = 400.0;
  VisualLoopDetector detector = VisualLoopDetector::create(camera).value();
  EXPECT_FALSE(detector.add(cv::Mat(), SE3()));
  cv::Mat image(480, 640, CV_8UC1, cv::Scalar(128));
  SE3 not_finite(SO3(), Eigen::Vector3d(NAN, 0.0, 0.0));
  EXPECT_FALSE(detector.add(image, not_finite));
  EXPECT_EQ(detector.size(), 0);
  EXPECT_TRUE(detector.add(image, SE3()));  // a blank image: a place without features
  EXPECT_EQ(detector.size(), 1);
}

}  // namespace
}  // namespace hanzo::fusion::vision
