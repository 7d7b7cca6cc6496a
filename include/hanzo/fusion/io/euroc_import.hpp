#pragma once
// EuRoC MAV / ASL dataset folders (the layout TUM-VI uses too):
//
//   DIR/mav0/imu0/data.csv      #timestamp [ns],w_RS_S_x,w_RS_S_y,w_RS_S_z,a_RS_S_x,a_RS_S_y,a_RS_S_z
//   DIR/mav0/imu0/sensor.yaml   T_BS, rate_hz, gyroscope_noise_density, accelerometer_noise_density
//   DIR/mav0/camN/data.csv      #timestamp [ns],filename   (images in camN/data/)
//   DIR/mav0/camN/sensor.yaml   T_BS, resolution, intrinsics [fu fv cu cv], distortion_model
//                               (radial-tangential | equidistant), distortion_coefficients
//   DIR/mav0/state_groundtruth_estimate0/data.csv   (else vicon0/) ground truth
//
// DIR may be the sequence folder or its mav0/. IMU rows become ImuMessages on imu_topic (rad/s,
// m/s^2, IMU frame; covariance per sample = noise_density^2 * rate_hz when sensor.yaml gives
// both), every camN folder becomes images on "/camN" (mono8 or rgb8; intrinsics and distortion
// from its sensor.yaml). Everything is written in time order across streams.
//
// Body frame = the frame sensor.yaml's T_BS refer to (EuRoC: the IMU). The calibration holds
// imu_to_body and camN_to_body = T_BS. Ground truth is returned as read (T_world_body).
// A row whose time does not increase is left out and counted per stream; a malformed row, an
// image that does not decode or a sensor.yaml that does not parse fails the import, naming
// file and line.

#include <cstdint>
#include <map>
#include <string>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::io {

struct EurocImportConfig {
  std::string imu_topic = "/imu";
  bool import_images = true;  ///< false: IMU (and ground truth) only
};

struct EurocStreamReport {
  std::string topic;
  uint64_t messages = 0;
  uint64_t rejected = 0;  ///< rows whose time did not increase
  std::string first_rejection;
};

struct EurocImportReport {
  std::vector<EurocStreamReport> streams;
  std::string ground_truth_path;   ///< empty when the folder has none
  Trajectory ground_truth;
  calib::Calibration calibration;  ///< imu and cameras to body
};

/// One camera's sensor.yaml (T_BS, intrinsics, distortion) as the calibration of `sensor_name`,
/// without importing anything; fails naming the file and field as import_euroc() does.
Result<calib::SensorCalibration> read_euroc_camera_calibration(const std::string& sensor_yaml_path, const std::string& sensor_name);

Result<EurocImportReport> import_euroc(const std::string& dir, SensorLogWriter& writer, const EurocImportConfig& config);

}  // namespace hanzo::fusion::io
