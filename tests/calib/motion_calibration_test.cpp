#include "hanzo/fusion/calib/motion_calibration.hpp"

#include <cmath>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/core/so3.hpp"
#include "support/calibration_motion.hpp"

namespace hanzo::fusion::calib {
namespace {

using ::testing::HasSubstr;

using test_support::CalibrationScenario;
using test_support::kDegToRad;

double rotation_error_deg(const MotionCalibrationSummary& summary, const SE3& truth) {
  return (truth.rotation().inverse() * summary.calibration.T_body_sensor().rotation()).angle() / kDegToRad;
}

TEST(MotionCalibration, RecoversExtrinsicsAndTimeOffsetFromBodyPoses) {
  CalibrationScenario scenario;
  MotionCalibrationInput input{"lidar", scenario.sensor_poses(), scenario.body_poses(), {}};
  const Result<MotionCalibrationSummary> summary = calibrate_from_motion(input);
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_LT(rotation_error_deg(*summary, scenario.T_body_sensor), 0.05);
  EXPECT_LT((summary->calibration.translation - scenario.T_body_sensor.translation()).norm(), 0.005);
  EXPECT_NEAR(summary->calibration.time_offset.seconds(), scenario.time_offset, 0.001);
  EXPECT_TRUE(summary->translation_estimated);
  EXPECT_FALSE(summary->unobservable_translation_axis.has_value());
  EXPECT_EQ(summary->calibration.sensor, "lidar");
  EXPECT_GT(summary->rotation_pairs, 200U);
  EXPECT_LT(summary->rotation_residual_rms_deg, 0.2);
  EXPECT_LT(summary->translation_residual_rms_m, 0.005);
}

TEST(MotionCalibration, RecoversRotationTimeOffsetAndGyroBiasFromTheGyroscope) {
  CalibrationScenario scenario;
  MotionCalibrationInput input{"camera_left", scenario.sensor_poses(), {}, scenario.gyro()};
  const Result<MotionCalibrationSummary> summary = calibrate_from_motion(input);
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_LT(rotation_error_deg(*summary, scenario.T_body_sensor), 0.1);
  EXPECT_NEAR(summary->calibration.time_offset.seconds(), scenario.time_offset, 0.001);
  EXPECT_LT((summary->gyro_bias - scenario.gyro_bias).norm(), 0.001);
  EXPECT_FALSE(summary->translation_estimated);
  EXPECT_EQ(summary->calibration.translation, Eigen::Vector3d::Zero());  // the prior: a gyroscope carries no translation

  // Without the bias the rotation is worse: the bias is what the alternation removes.
  MotionCalibrationConfig no_bias;
  no_bias.estimate_gyro_bias = false;
  const Result<MotionCalibrationSummary> biased = calibrate_from_motion(input, no_bias);
  ASSERT_TRUE(biased.ok()) << biased.error().message;
  EXPECT_GT(biased->rotation_residual_rms_deg, 2.0 * summary->rotation_residual_rms_deg);
}

TEST(MotionCalibration, OdometryGlitchesAreRejectedAsOutliers) {
  CalibrationScenario scenario;
  std::vector<StampedPose> sensor = scenario.sensor_poses();
  for (std::size_t i = 7; i < sensor.size(); i += 37) {  // a 4 degree jump now and then
    sensor[i].pose.rotation() = sensor[i].pose.rotation() * SO3::exp(Eigen::Vector3d(0.0, 4.0 * kDegToRad, 0.0));
  }
  MotionCalibrationInput input{"lidar", sensor, scenario.body_poses(), {}};
  const Result<MotionCalibrationSummary> summary = calibrate_from_motion(input);
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_GE(summary->outlier_pairs, 10U);
  EXPECT_LT(rotation_error_deg(*summary, scenario.T_body_sensor), 0.1);
  EXPECT_NEAR(summary->calibration.time_offset.seconds(), scenario.time_offset, 0.002);
}

TEST(MotionCalibration, NearlyPlanarMotionKeepsTheVerticalTranslationFromThePrior) {
  CalibrationScenario scenario;
  scenario.body.roll_pitch = 0.03;  // a vehicle turning, rocking by about a degree (axis spread 0.03)
  MotionCalibrationConfig config;
  config.prior_translation = Eigen::Vector3d(0.0, 0.0, 0.25);
  MotionCalibrationInput input{"lidar", scenario.sensor_poses(), scenario.body_poses(), {}};
  const Result<MotionCalibrationSummary> summary = calibrate_from_motion(input, config);
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_LT(rotation_error_deg(*summary, scenario.T_body_sensor), 1.0);  // measured 0.38
  ASSERT_TRUE(summary->unobservable_translation_axis.has_value());
  EXPECT_GT(std::abs(summary->unobservable_translation_axis->z()), 0.95);
  EXPECT_LT(summary->translation_observability, config.min_translation_observability);
  const Eigen::Vector3d& translation = summary->calibration.translation;
  EXPECT_NEAR(translation.x(), 0.12, 0.01);
  EXPECT_NEAR(translation.y(), -0.05, 0.01);
  EXPECT_NEAR(translation.z(), 0.25, 0.02);  // the prior, not the truth 0.30: the motion cannot tell
}

TEST(MotionCalibration, RotationAboutOneAxisOnlyIsRefused) {
  CalibrationScenario scenario;
  scenario.body.roll_pitch = 0.0;
  MotionCalibrationInput input{"lidar", scenario.sensor_poses(), scenario.body_poses(), {}};
  const Result<MotionCalibrationSummary> summary = calibrate_from_motion(input);
  ASSERT_FALSE(summary.ok());
  EXPECT_THAT(summary.error().message, HasSubstr("one axis"));
}

TEST(MotionCalibration, BadInputIsRefusedByName) {
  CalibrationScenario scenario;
  const std::vector<StampedPose> sensor = scenario.sensor_poses();
  const std::vector<StampedPose> body = scenario.body_poses();
  const auto error = [](const MotionCalibrationInput& input, const MotionCalibrationConfig& config = {}) {
    const Result<MotionCalibrationSummary> summary = calibrate_from_motion(input, config);
    return summary.ok() ? std::string("(calibrated)") : summary.error().message;
  };
  EXPECT_THAT(error({"lidar", sensor, {}, {}}), HasSubstr("exactly one"));
  EXPECT_THAT(error({"lidar", sensor, body, scenario.gyro()}), HasSubstr("exactly one"));
  EXPECT_THAT(error({"", sensor, body, {}}), HasSubstr("sensor"));

  std::vector<StampedPose> repeated = sensor;
  repeated[12].time = repeated[11].time;
  EXPECT_THAT(error({"lidar", repeated, body, {}}), HasSubstr("sensor_poses[12]: timestamp"));
  std::vector<StampedPose> not_finite = body;
  not_finite[40].pose.translation().x() = std::nan("");
  EXPECT_THAT(error({"lidar", sensor, not_finite, {}}), HasSubstr("body_poses[40]: non-finite"));

  std::vector<StampedPose> later = body;  // an hour later: nothing overlaps
  for (StampedPose& pose : later) pose.time += Duration::from_seconds(3600.0);
  EXPECT_THAT(error({"lidar", sensor, later, {}}), HasSubstr("overlap"));

  std::vector<StampedPose> still = sensor;  // the sensor did not move
  for (StampedPose& pose : still) pose.pose = sensor.front().pose;
  EXPECT_THAT(error({"lidar", still, body, {}}), HasSubstr("must rotate"));

  MotionCalibrationConfig bad;
  bad.max_time_offset = -1.0;
  EXPECT_THAT(error({"lidar", sensor, body, {}}, bad), HasSubstr("max_time_offset"));
  bad = {};
  bad.pair_interval = 0.0;
  EXPECT_THAT(error({"lidar", sensor, body, {}}, bad), HasSubstr("pair_interval"));
}

}  // namespace
}  // namespace hanzo::fusion::calib
