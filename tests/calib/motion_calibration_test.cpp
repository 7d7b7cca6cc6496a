#include "hanzo/fusion/calib/motion_calibration.hpp"

#include <cmath>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/core/so3.hpp"

namespace hanzo::fusion::calib {
namespace {

using ::testing::HasSubstr;

constexpr double kDegToRad = M_PI / 180.0;
const Timestamp kStart = Timestamp::from_seconds(1700000000.0);

// A body swinging about all three axes while it moves: R_world_body = Exp(phi(t)), so its
// body-frame angular velocity is J_r(phi) phi'(t) exactly. `roll_pitch` scales the swing
// about x and y (0: it turns about its vertical only).
struct BodyTrajectory {
  double roll_pitch = 1.0;

  Eigen::Vector3d phi(double t) const {
    return {roll_pitch * 0.5 * std::sin(1.3 * t), roll_pitch * 0.4 * std::sin(0.9 * t + 1.0), 1.2 * std::sin(0.45 * t)};
  }
  Eigen::Vector3d phi_rate(double t) const {
    return {roll_pitch * 0.65 * std::cos(1.3 * t), roll_pitch * 0.36 * std::cos(0.9 * t + 1.0), 0.54 * std::cos(0.45 * t)};
  }
  SE3 pose(double t) const {
    return SE3(SO3::exp(phi(t)), Eigen::Vector3d(3.0 * std::sin(0.3 * t), 2.0 * std::cos(0.4 * t) - 2.0, 0.4 * std::sin(0.7 * t)));
  }
  Eigen::Vector3d angular_velocity(double t) const { return SO3::right_jacobian(phi(t)) * phi_rate(t); }
};

struct Scenario {
  BodyTrajectory body;
  SE3 T_body_sensor{SO3::exp(Eigen::Vector3d(0.3, -1.2, 2.0)), Eigen::Vector3d(0.12, -0.05, 0.30)};
  double time_offset = -0.0237;  // t_body = t_sensor + offset
  double duration = 60.0;
  double sensor_rate = 10.0;
  double sensor_position_noise = 0.001;             // m
  double sensor_rotation_noise = 0.05 * kDegToRad;  // rad
  Eigen::Vector3d gyro_bias{0.010, -0.020, 0.005};  // rad/s
  double gyro_noise = 0.005;                        // rad/s per sample
  std::mt19937 random{7};

  // The sensor's own odometry: T_odom_sensor(t_s) = T_odom_world T_world_body(t_s + offset) X, noisy.
  std::vector<StampedPose> sensor_poses() {
    std::normal_distribution<double> normal;
    const SE3 T_odom_world(SO3::exp(Eigen::Vector3d(0.2, 0.1, -0.7)), Eigen::Vector3d(5.0, -3.0, 1.0));
    std::vector<StampedPose> poses;
    for (double t = 0.5; t < duration - 0.5; t += 1.0 / sensor_rate) {
      SE3 pose = T_odom_world * body.pose(t + time_offset) * T_body_sensor;
      const Eigen::Vector3d rotation_noise(normal(random), normal(random), normal(random));
      const Eigen::Vector3d position_noise(normal(random), normal(random), normal(random));
      pose = SE3(pose.rotation() * SO3::exp(rotation_noise * sensor_rotation_noise),
                 pose.translation() + position_noise * sensor_position_noise);
      poses.push_back({kStart + Duration::from_seconds(t), pose});
    }
    return poses;
  }
  std::vector<StampedPose> body_poses(double rate = 100.0) const {
    std::vector<StampedPose> poses;
    for (double t = 0.0; t <= duration; t += 1.0 / rate) poses.push_back({kStart + Duration::from_seconds(t), body.pose(t)});
    return poses;
  }
  std::vector<GyroSample> gyro(double rate = 200.0) {
    std::normal_distribution<double> normal;
    std::vector<GyroSample> samples;
    for (double t = 0.0; t <= duration; t += 1.0 / rate) {
      const Eigen::Vector3d noise(normal(random), normal(random), normal(random));
      samples.push_back({kStart + Duration::from_seconds(t), body.angular_velocity(t) + gyro_bias + noise * gyro_noise});
    }
    return samples;
  }
};

double rotation_error_deg(const MotionCalibrationSummary& summary, const SE3& truth) {
  return (truth.rotation().inverse() * summary.calibration.T_body_sensor().rotation()).angle() / kDegToRad;
}

TEST(MotionCalibration, RecoversExtrinsicsAndTimeOffsetFromBodyPoses) {
  Scenario scenario;
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
  Scenario scenario;
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
  Scenario scenario;
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
  Scenario scenario;
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
  Scenario scenario;
  scenario.body.roll_pitch = 0.0;
  MotionCalibrationInput input{"lidar", scenario.sensor_poses(), scenario.body_poses(), {}};
  const Result<MotionCalibrationSummary> summary = calibrate_from_motion(input);
  ASSERT_FALSE(summary.ok());
  EXPECT_THAT(summary.error().message, HasSubstr("one axis"));
}

TEST(MotionCalibration, BadInputIsRefusedByName) {
  Scenario scenario;
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
