#pragma once
// Calibration: where each sensor sits on the body and how its clock relates to the body
// clock, in the spec's calibration YAML ("Calibration storage"):
//
//   calibration:
//     lidar_to_body:
//       rotation: [0.707, 0.0, 0.707, 0.0]  # quaternion w, x, y, z of R_body_lidar
//       translation: [0.1, 0.0, 0.3]         # meters, lidar origin in the body frame
//       time_offset_ns: -5000000             # t_body = t_lidar + time_offset_ns
//     camera_left_to_body:
//       ...
//       intrinsics: {fx, fy, cx, cy, distortion_model: equidistant|radtan|none, distortion_coeffs: [...]}
//
// Each "<sensor>_to_body" entry is the transform T_body_sensor (maps sensor coordinates into
// the body frame). Defaults: rotation identity, translation zero, time_offset_ns 0 (so
// `imu_to_body: {}` is the identity). A rotation whose norm differs from 1 by more than
// msgs::kUnitQuaternionTolerance (1e-3) is rejected, never silently normalized; within the
// tolerance (3-decimal values such as 0.707) it is kept as written and normalized when used.
// Full reference: docs/calibration.md.

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::calib {

struct CameraCalibration {
  msgs::CameraIntrinsics intrinsics;
  msgs::DistortionModel distortion;

  /// The projection model of these intrinsics (radtan's k3 is 0 when four coefficients are
  /// given). Expects a validated calibration (validate(): known model, its coefficient count).
  PinholeCamera pinhole_camera() const;
};

struct SensorCalibration {
  std::string sensor;  // "lidar" for the key "lidar_to_body"; matches the configuration's sensor name
  Eigen::Vector4d rotation_wxyz{1.0, 0.0, 0.0, 0.0};           // R_body_sensor as written
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();       // meters, in the body frame
  Duration time_offset;                                        // t_body = t_sensor + time_offset
  std::optional<CameraCalibration> camera;                     // cameras only

  /// T_body_sensor with the rotation normalized.
  SE3 T_body_sensor() const;
  static SensorCalibration from_transform(std::string sensor, const SE3& T_body_sensor, Duration time_offset = {});
};

struct Calibration {
  std::vector<SensorCalibration> sensors;  // in file order

  const SensorCalibration* find(std::string_view sensor) const;
};

/// The loader's rules for a calibration built in code: unique non-empty names, finite values,
/// unit rotations (within tolerance), valid camera intrinsics and distortion.
Status validate(const Calibration& calibration);

Result<Calibration> load_calibration(const std::string& path);
Result<Calibration> parse_calibration(const std::string& yaml_text, const std::string& source_name);
/// The spec's layout; parse_calibration(to_yaml(c)) reproduces c exactly.
std::string to_yaml(const Calibration& calibration);
/// Validates, then writes to_yaml(calibration) atomically.
Status save_calibration(const Calibration& calibration, const std::string& path);

}  // namespace hanzo::fusion::calib
