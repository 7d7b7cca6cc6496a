#include "hanzo/fusion/calib/calibration.hpp"

#include <algorithm>
#include <cmath>
#include <set>

#include <fmt/format.h>

#include "hanzo/fusion/msgs/validate.hpp"

namespace hanzo::fusion::calib {

PinholeCamera CameraCalibration::pinhole_camera() const {
  PinholeCamera camera;
  camera.fx = intrinsics.fx;
  camera.fy = intrinsics.fy;
  camera.cx = intrinsics.cx;
  camera.cy = intrinsics.cy;
  switch (distortion.type) {
    case msgs::DistortionType::kNone: camera.distortion = PinholeCamera::Distortion::kNone; break;
    case msgs::DistortionType::kRadtan: camera.distortion = PinholeCamera::Distortion::kRadtan; break;
    case msgs::DistortionType::kEquidistant: camera.distortion = PinholeCamera::Distortion::kEquidistant; break;
  }
  for (std::size_t i = 0; i < std::min(distortion.coefficients.size(), camera.coefficients.size()); ++i) {
    camera.coefficients[i] = distortion.coefficients[i];
  }
  return camera;
}

SE3 SensorCalibration::T_body_sensor() const {
  const Eigen::Quaterniond q(rotation_wxyz[0], rotation_wxyz[1], rotation_wxyz[2], rotation_wxyz[3]);
  return {SO3::from_quaternion_normalized(q), translation};
}

SensorCalibration SensorCalibration::from_transform(std::string sensor, const SE3& T_body_sensor, Duration time_offset) {
  SensorCalibration calibration;
  calibration.sensor = std::move(sensor);
  calibration.rotation_wxyz = T_body_sensor.rotation().wxyz();
  calibration.translation = T_body_sensor.translation();
  calibration.time_offset = time_offset;
  return calibration;
}

const SensorCalibration* Calibration::find(std::string_view sensor) const {
  for (const SensorCalibration& entry : sensors) {
    if (entry.sensor == sensor) return &entry;
  }
  return nullptr;
}

Status validate(const Calibration& calibration) {
  std::set<std::string_view> names;
  for (const SensorCalibration& entry : calibration.sensors) {
    const std::string field = fmt::format("{}_to_body", entry.sensor);
    const auto fail = [&](std::string_view sub_field, std::string_view what) -> Status {
      return Error{fmt::format("Calibration.{}.{}: {}", field, sub_field, what), fmt::format("{}.{}", field, sub_field)};
    };
    if (entry.sensor.empty()) return Error{"Calibration: an entry has an empty sensor name", "sensor"};
    if (!names.insert(entry.sensor).second) return Error{fmt::format("Calibration.{}: duplicate sensor", field), field};
    if (!entry.rotation_wxyz.allFinite()) return fail("rotation", "non-finite value");
    const double norm = entry.rotation_wxyz.norm();
    if (std::abs(norm - 1.0) > msgs::kUnitQuaternionTolerance) {
      return fail("rotation", fmt::format("quaternion norm {} (expected a unit quaternion)", norm));
    }
    if (!entry.translation.allFinite()) return fail("translation", "non-finite value");
    if (entry.camera) {
      HANZO_RETURN_IF_ERROR(msgs::validate(entry.camera->intrinsics, field + ".intrinsics"));
      HANZO_RETURN_IF_ERROR(msgs::validate(entry.camera->distortion, field + ".intrinsics"));
    }
  }
  return ok_status();
}

}  // namespace hanzo::fusion::calib
