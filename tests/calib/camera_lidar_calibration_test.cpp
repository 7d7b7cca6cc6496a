// Camera-LiDAR calibration on the simulated board stations (examples/scenarios/camera_lidar_board.yaml:
// a VLP-16 with 2 cm range noise and a camera with EuRoC's lens, ten stations in front of a
// 1.1 x 0.9 m board carrying an 8 x 6 inner-corner pattern): the LiDAR's pose in the camera's frame
// within 1 cm and 0.5 deg of the truth (the target), found by the board's size or from a
// rough guess; a wrong board size is not certified; too few stations and bad settings are
// refused by name; the constraint's Jacobian matches numeric differences.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/calib/camera_lidar_calibration.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"

namespace hanzo::fusion::calib {
namespace {

using ::testing::HasSubstr;

constexpr double kDegree = 3.14159265358979323846 / 180.0;

struct BoardLog {
  std::vector<msgs::ImageMessage> images;
  std::vector<msgs::PointCloudMessage> scans;
  msgs::CameraIntrinsics intrinsics;
  msgs::DistortionModel distortion;
  SE3 T_camera_lidar;  // truth
  std::vector<BoardObservation> boards;  // observe_board on the images, once for every test
};

CameraLidarCalibrationConfig board_config() {
  CameraLidarCalibrationConfig config;
  config.target = {8, 6, 0.10};
  config.board_width = 1.1;
  config.board_height = 0.9;
  return config;
}

const BoardLog& board_log() {
  static const BoardLog log = [] {
    BoardLog made;
    Result<sim::Scenario> scenario = sim::load_scenario("examples/scenarios/camera_lidar_board.yaml");
    EXPECT_TRUE(scenario) << scenario.error().message;
    SE3 T_body_camera, T_body_lidar;
    for (const sim::ScenarioSensor& sensor : scenario->sensors) {
      if (sensor.name == "camera") {
        const auto& camera = std::get<sim::CameraSimulatorConfig>(sensor.simulator);
        made.intrinsics = camera.intrinsics;
        made.distortion = camera.distortion;
        T_body_camera = sensor.T_body_sensor;
      }
      if (sensor.name == "lidar") T_body_lidar = sensor.T_body_sensor;
    }
    made.T_camera_lidar = T_body_camera.inverse() * T_body_lidar;
    auto simulation = sim::ScenarioSimulation::create(std::move(*scenario));
    EXPECT_TRUE(simulation);
    const Status status = (*simulation)->run([&made](const sim::ScenarioSensor&, msgs::SensorMessage&& message) -> Status {
      if (auto* image = std::get_if<msgs::ImageMessage>(&message)) made.images.push_back(std::move(*image));
      if (auto* scan = std::get_if<msgs::PointCloudMessage>(&message)) made.scans.push_back(std::move(*scan));
      return ok_status();
    });
    EXPECT_TRUE(status);
    Result<std::vector<BoardObservation>> boards = observe_board(made.images, made.intrinsics, made.distortion, board_config().target);
    EXPECT_TRUE(boards) << boards.error().message;
    made.boards = std::move(*boards);
    return made;
  }();
  return log;
}

void expect_near_truth(const CameraLidarCalibrationResult& result, const SE3& truth) {
  const SE3 error = truth.inverse() * result.T_camera_lidar;
  EXPECT_LT(error.translation().norm(), 0.01);
  EXPECT_LT(error.rotation().angle(), 0.5 * kDegree);
  // The jackknife's bounds are of the error's size, not orders away.
  const Eigen::Matrix<double, 6, 1> sigma = result.covariance.diagonal().cwiseSqrt();
  EXPECT_LT(sigma.head<3>().maxCoeff(), 0.01);
  EXPECT_GT(sigma.head<3>().maxCoeff(), 1e-5);
  EXPECT_LT(sigma.tail<3>().maxCoeff(), 0.5 * kDegree);
}

TEST(CameraLidarCalibration, RecoversTheLidarPoseFromBoardStationsFoundByTheBoardsSize) {
  const BoardLog& log = board_log();
  ASSERT_GT(log.images.size(), 200U);
  ASSERT_GT(log.scans.size(), 200U);
  auto result = calibrate_camera_lidar(log.boards, log.scans, board_config());
  ASSERT_TRUE(result) << result.error().message;
  EXPECT_GT(result->images_with_board, 200U);
  expect_near_truth(*result, log.T_camera_lidar);
  EXPECT_TRUE(result->certified) << result->not_certified_reason;
  EXPECT_GE(result->stations, 8U);
  // Scans while the rig moves are left out and counted.
  EXPECT_GT(result->scans_board_moving, 50U);
  EXPECT_EQ(result->scans_static, result->scans_used + result->scans_board_not_in_lidar);
  EXPECT_EQ(result->views.size(), result->scans_used);
  EXPECT_LT(std::abs(result->edge_bias_m), 0.005);  // half a ring step added back
  EXPECT_LT(result->plane_rms_m, 0.03);             // the 2 cm range noise
  EXPECT_LT(result->edge_rms_m, 0.01);
  EXPECT_GT(result->normal_spread_deg, 20.0);
}

TEST(CameraLidarCalibration, StartsFromARoughGuess) {
  const BoardLog& log = board_log();
  CameraLidarCalibrationConfig config = board_config();
  Eigen::Matrix<double, 6, 1> off;
  off << 0.12, -0.08, 0.1, 5.0 * kDegree, -6.0 * kDegree, 4.0 * kDegree;
  config.initial_T_camera_lidar = log.T_camera_lidar * SE3::exp(off);
  auto result = calibrate_camera_lidar(log.boards, log.scans, config);
  ASSERT_TRUE(result) << result.error().message;
  expect_near_truth(*result, log.T_camera_lidar);
  EXPECT_TRUE(result->certified) << result->not_certified_reason;
}

TEST(CameraLidarCalibration, AWrongBoardSizeIsNotCertified) {
  const BoardLog& log = board_log();
  CameraLidarCalibrationConfig config = board_config();
  config.board_width = 0.9;  // the pattern's extent: the white border left out
  config.board_height = 0.7;
  auto result = calibrate_camera_lidar(log.boards, log.scans, config);
  ASSERT_TRUE(result) << result.error().message;
  EXPECT_FALSE(result->certified);
  EXPECT_NEAR(result->edge_bias_m, 0.1, 0.03);  // the 10 cm border
  EXPECT_THAT(result->not_certified_reason, HasSubstr("check the board size"));
}

TEST(CameraLidarCalibration, RefusesTooFewStationsAndBadSettingsByName) {
  const BoardLog& log = board_log();
  // The first two stations only (each holds 1.5 s, then 1 s of moving).
  const Timestamp cut = log.scans.front().timestamp + Duration::from_seconds(4.0);
  std::vector<BoardObservation> images;
  std::vector<msgs::PointCloudMessage> scans;
  for (const auto& board : log.boards) {
    if (board.time < cut) images.push_back(board);
  }
  for (const auto& scan : log.scans) {
    if (scan.timestamp < cut) scans.push_back(scan);
  }
  auto few = calibrate_camera_lidar(images, scans, board_config());
  ASSERT_FALSE(few);
  EXPECT_THAT(few.error().message, HasSubstr("the board was seen by both sensors at 2 station(s); 4 are needed"));
  // The same from the images themselves.
  std::vector<msgs::ImageMessage> first_images;
  for (const auto& image : log.images) {
    if (image.timestamp < cut) first_images.push_back(image);
  }
  auto few_images = calibrate_camera_lidar(first_images, log.intrinsics, log.distortion, scans, board_config());
  ASSERT_FALSE(few_images);
  EXPECT_EQ(few_images.error().message, few.error().message);
  msgs::ImageMessage depth = first_images.front();
  depth.encoding = msgs::ImageEncoding::kDepth32f;
  auto not_intensity = calibrate_camera_lidar({depth}, log.intrinsics, log.distortion, scans, board_config());
  ASSERT_FALSE(not_intensity);
  EXPECT_THAT(not_intensity.error().message, HasSubstr("images[0]"));

  CameraLidarCalibrationConfig narrow = board_config();
  narrow.board_width = 0.5;
  auto bad = calibrate_camera_lidar(images, scans, narrow);
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().field, "board_width");
  EXPECT_THAT(bad.error().message, HasSubstr("narrower than the pattern"));

  auto no_scans = calibrate_camera_lidar(images, {}, board_config());
  ASSERT_FALSE(no_scans);
  EXPECT_THAT(no_scans.error().message, HasSubstr("scans: none given"));
  std::vector<msgs::PointCloudMessage> empty_scan(1);
  auto empty = calibrate_camera_lidar(images, empty_scan, board_config());
  ASSERT_FALSE(empty);
  EXPECT_THAT(empty.error().message, HasSubstr("scans[0]: no points"));
}

TEST(CameraLidarCalibration, ConstraintJacobianMatchesNumericDifferences) {
  const SE3 T(SO3::exp(Eigen::Vector3d(0.3, -1.2, 0.7)), Eigen::Vector3d(0.1, -0.2, 0.05));
  const Eigen::Vector3d point(2.0, -0.4, 0.9), direction = Eigen::Vector3d(0.2, -0.5, 0.8).normalized();
  Eigen::Matrix<double, 1, 6> analytic;
  point_constraint_residual(T, point, direction, 0.3, &analytic);
  constexpr double kStep = 1e-6;
  for (int k = 0; k < 6; ++k) {
    Eigen::Matrix<double, 6, 1> delta = Eigen::Matrix<double, 6, 1>::Zero();
    delta(k) = kStep;
    const double numeric = (point_constraint_residual(T * SE3::exp(delta), point, direction, 0.3) -
                            point_constraint_residual(T * SE3::exp(-delta), point, direction, 0.3)) /
                           (2.0 * kStep);
    EXPECT_NEAR(analytic(k), numeric, 1e-7) << k;
  }
}

}  // namespace
}  // namespace hanzo::fusion::calib
