#include "hanzo/fusion/calib/calibration.hpp"

#include <filesystem>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::calib {
namespace {

using ::testing::HasSubstr;

std::string error_of(const std::string& yaml) {
  const Result<Calibration> calibration = parse_calibration(yaml, "calibration.yaml");
  return calibration.ok() ? std::string("(loaded)") : calibration.error().message;
}

TEST(Calibration, SpecExampleLoadsUnchanged) {
  const Result<Calibration> loaded = load_calibration("examples/calibration.yaml");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  ASSERT_EQ(loaded->sensors.size(), 3U);
  const SensorCalibration* lidar = loaded->find("lidar");
  ASSERT_NE(lidar, nullptr);
  EXPECT_EQ(lidar->time_offset.nanoseconds(), -5'000'000);
  EXPECT_EQ(lidar->translation, Eigen::Vector3d(0.1, 0.0, 0.3));
  // [0.707, 0, 0.707, 0] is a 90 degree rotation about y, rounded to 3 decimals.
  const SE3 T_body_lidar = lidar->T_body_sensor();
  EXPECT_NEAR(T_body_lidar.rotation().angle(), std::numbers::pi / 2.0, 1e-3);
  EXPECT_LT((T_body_lidar * Eigen::Vector3d::UnitX() - Eigen::Vector3d(0.1, 0.0, 0.3 - 1.0)).norm(), 1e-3);
  const SensorCalibration* camera = loaded->find("camera_left");
  ASSERT_NE(camera, nullptr);
  ASSERT_TRUE(camera->camera.has_value());
  EXPECT_EQ(camera->camera->intrinsics.fx, 458.654);
  EXPECT_EQ(camera->camera->intrinsics.cy, 248.375);
  EXPECT_EQ(camera->camera->distortion.type, msgs::DistortionType::kEquidistant);
  EXPECT_EQ(camera->camera->distortion.coefficients, (std::vector<double>{-0.28340, 0.07395, 0.00019, 0.00001}));
  EXPECT_EQ(camera->time_offset.nanoseconds(), -12'000'000);
  // Camera optical frame (z forward) -> body FLU: the optical axis looks along body x.
  EXPECT_LT((camera->T_body_sensor().rotation() * Eigen::Vector3d::UnitZ() - Eigen::Vector3d::UnitX()).norm(), 1e-12);
  EXPECT_FALSE(loaded->find("imu")->camera.has_value());
  EXPECT_TRUE(validate(*loaded).ok());
}

TEST(Calibration, EachRuleGivesItsDocumentedError) {
  EXPECT_EQ(error_of("calibration:\n  lidar_to_body:\n    rotation: [0.707, 0.0, 0.707]\n"),
            "calibration.yaml:3: lidar_to_body.rotation: expected 4 numbers (w, x, y, z), got 3");
  // Not a unit quaternion: rejected, not normalized.
  EXPECT_EQ(error_of("calibration:\n  lidar_to_body:\n    rotation: [0.7, 0.0, 0.7, 0.0]\n"),
            "calibration.yaml:3: lidar_to_body.rotation: expected a unit quaternion (w, x, y, z), got norm 0.989949");
  EXPECT_EQ(error_of("calibration:\n  lidar_to_body:\n    translation: [0.1, 0.0]\n"),
            "calibration.yaml:3: lidar_to_body.translation: expected 3 numbers (x, y, z), got 2");
  EXPECT_EQ(error_of("calibration:\n  lidar_to_body:\n    time_offset_ns: -5.5e6\n"),
            "calibration.yaml:3: lidar_to_body.time_offset_ns: expected an integer, got '-5.5e6'");
  EXPECT_EQ(error_of("calibration:\n  lidar:\n    rotation: [1, 0, 0, 0]\n"),
            "calibration.yaml:2: lidar: expected an entry named <sensor>_to_body (for example lidar_to_body)");
  EXPECT_EQ(error_of("calibration:\n  lidar_to_body:\n    rotaton: [1, 0, 0, 0]\n"),
            "calibration.yaml:3: lidar_to_body.rotaton: unknown key (expected one of: rotation, translation, "
            "time_offset_ns, intrinsics)");
  const std::string camera = "calibration:\n  camera_to_body:\n    intrinsics:\n      fx: 400\n      fy: 400\n      cx: 320\n      cy: 240\n";
  EXPECT_EQ(error_of(camera + "      distortion_model: fisheye\n      distortion_coeffs: [0, 0, 0, 0]\n"),
            "calibration.yaml:8: camera_to_body.intrinsics.distortion_model: expected equidistant, radtan or none, got 'fisheye'");
  EXPECT_EQ(error_of(camera + "      distortion_model: radtan\n      distortion_coeffs: [0.1, 0.2, 0.3]\n"),
            "calibration.yaml:9: camera_to_body.intrinsics.distortion_coeffs: model radtan takes 4 or 5 coefficients "
            "(k1, k2, p1, p2[, k3]), got 3");
  EXPECT_EQ(error_of(camera + "      distortion_coeffs: [0.1, 0.2, 0.3, 0.4]\n"),
            "calibration.yaml:3: camera_to_body.intrinsics.distortion_model: missing (distortion_coeffs needs a "
            "distortion_model: equidistant or radtan)");
  EXPECT_EQ(error_of("calibration:\n  camera_to_body:\n    intrinsics:\n      fx: 400\n      fy: 400\n      cx: 320\n"),
            "calibration.yaml:3: camera_to_body.intrinsics.cy: missing (expected a number)");
  EXPECT_EQ(error_of("calibration:\n  camera_to_body:\n    intrinsics:\n      fx: -400\n      fy: 400\n      cx: 320\n      cy: 240\n"),
            "calibration.yaml:4: camera_to_body.intrinsics.fx: expected a positive focal length in pixels, got -400");
  EXPECT_EQ(error_of("calibration:\n  camera_to_body:\n    intrinsics:\n      fx: 400\n      fy: 400\n      cx: 700\n      cy: 240\n"
                     "      width: 640\n      height: 480\n"),
            "calibration.yaml:6: camera_to_body.intrinsics.cx: principal point 700 outside the image width 640");
  EXPECT_EQ(error_of("calibration:\n  imu_to_body:\n    translation: [.nan, 0, 0]\n"),
            "calibration.yaml:3: imu_to_body.translation: item 0: expected a finite number, got '.nan'");
  EXPECT_EQ(error_of("calibration:\n  imu_to_body: 5\n"),
            "calibration.yaml:2: imu_to_body: expected a map with rotation, translation, time_offset_ns (and intrinsics "
            "for cameras), or 'identity'");
  EXPECT_EQ(error_of("sensors: {}\n"), "calibration.yaml:1: sensors: unknown key (expected one of: calibration)");
  EXPECT_THAT(error_of("calibration:\n  imu_to_body: {rotation: [1, 0\n"), HasSubstr("YAML syntax error"));
}

TEST(Calibration, LoadSaveLoadIsLossless) {
  Calibration calibration = load_calibration("examples/calibration.yaml").value();
  SensorCalibration radar = SensorCalibration::from_transform("radar", SE3(SO3::exp({0.0, 0.0, 0.25}), {2.1, 0.0, 0.4}),
                                                              Duration::from_nanoseconds(123));
  calibration.sensors.push_back(radar);
  SensorCalibration pinhole;
  pinhole.sensor = "camera_rear";
  pinhole.camera = CameraCalibration{{500.0, 500.0, 320.5, 240.5, 640, 480}, {msgs::DistortionType::kRadtan, {0.1, -0.2, 0.001, 0.002, 0.05}}};
  calibration.sensors.push_back(pinhole);

  const std::filesystem::path path = std::filesystem::temp_directory_path() / "hanzo_calibration_test.yaml";
  ASSERT_TRUE(save_calibration(calibration, path.string()).ok());
  const Result<Calibration> loaded = load_calibration(path.string());
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  ASSERT_EQ(loaded->sensors.size(), calibration.sensors.size());
  for (size_t i = 0; i < calibration.sensors.size(); ++i) {
    const SensorCalibration& a = calibration.sensors[i];
    const SensorCalibration& b = loaded->sensors[i];
    EXPECT_EQ(a.sensor, b.sensor);
    EXPECT_EQ(a.rotation_wxyz, b.rotation_wxyz);  // kept exactly as written, 0.707 included
    EXPECT_EQ(a.translation, b.translation);
    EXPECT_EQ(a.time_offset, b.time_offset);
    ASSERT_EQ(a.camera.has_value(), b.camera.has_value());
    if (a.camera) {
      EXPECT_EQ(a.camera->intrinsics.fx, b.camera->intrinsics.fx);
      EXPECT_EQ(a.camera->intrinsics.cx, b.camera->intrinsics.cx);
      EXPECT_EQ(a.camera->intrinsics.width, b.camera->intrinsics.width);
      EXPECT_EQ(a.camera->distortion.type, b.camera->distortion.type);
      EXPECT_EQ(a.camera->distortion.coefficients, b.camera->distortion.coefficients);
    }
  }
  EXPECT_EQ(to_yaml(*loaded), to_yaml(calibration));
  std::filesystem::remove(path);
}

TEST(Calibration, ValidateCatchesBadCalibrationsBuiltInCode) {
  Calibration calibration;
  calibration.sensors.push_back(SensorCalibration::from_transform("lidar", SE3()));
  calibration.sensors.push_back(SensorCalibration::from_transform("lidar", SE3()));
  EXPECT_THAT(validate(calibration).error().message, HasSubstr("duplicate sensor"));
  calibration.sensors.pop_back();
  calibration.sensors[0].rotation_wxyz = {2.0, 0.0, 0.0, 0.0};
  EXPECT_EQ(validate(calibration).error().field, "lidar_to_body.rotation");
  EXPECT_FALSE(save_calibration(calibration, "/tmp/never-written.yaml").ok());
  EXPECT_FALSE(std::filesystem::exists("/tmp/never-written.yaml"));
}

}  // namespace
}  // namespace hanzo::fusion::calib
