// hanzo-fusion calib check FILE: loads a calibration file and prints its summary (calib motion:
// calib_motion_command.cpp; calib camera: calib_camera_command.cpp).

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <memory>
#include <numbers>
#include <string>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/calib/calibration.hpp"

namespace hanzo::fusion::app {
namespace {

nlohmann::json to_json(const calib::Calibration& calibration) {
  nlohmann::json sensors = nlohmann::json::array();
  for (const calib::SensorCalibration& entry : calibration.sensors) {
    const Eigen::Vector4d& q = entry.rotation_wxyz;
    nlohmann::json item = {{"sensor", entry.sensor},
                           {"rotation_wxyz", {q[0], q[1], q[2], q[3]}},
                           {"rotation_angle_deg", entry.T_body_sensor().rotation().angle() * 180.0 / std::numbers::pi},
                           {"translation", {entry.translation.x(), entry.translation.y(), entry.translation.z()}},
                           {"time_offset_ns", entry.time_offset.nanoseconds()}};
    if (entry.camera) {
      const msgs::CameraIntrinsics& k = entry.camera->intrinsics;
      item["intrinsics"] = {{"fx", k.fx}, {"fy", k.fy}, {"cx", k.cx}, {"cy", k.cy}, {"width", k.width}, {"height", k.height},
                            {"distortion_model", msgs::to_string(entry.camera->distortion.type)},
                            {"distortion_coeffs", entry.camera->distortion.coefficients}};
    }
    sensors.push_back(std::move(item));
  }
  return {{"sensors", sensors}};
}

std::string to_text(const std::string& path, const calib::Calibration& calibration) {
  std::string text = fmt::format("{}: valid calibration, {} sensor(s)\n", path, calibration.sensors.size());
  for (const calib::SensorCalibration& entry : calibration.sensors) {
    const SO3 rotation = entry.T_body_sensor().rotation();
    const std::string rotation_text =
        rotation.angle() == 0.0 ? std::string("identity")
                                : fmt::format("{:.3f} deg about [{:.3f}]", rotation.angle() * 180.0 / std::numbers::pi,
                                              fmt::join(rotation.log().normalized(), ", "));
    text += fmt::format("  {}: T_body_{} rotation {}, translation [{}] m, time offset {:.3f} ms\n", entry.sensor, entry.sensor,
                        rotation_text, fmt::join(entry.translation, ", "),
                        static_cast<double>(entry.time_offset.nanoseconds()) * 1e-6);
    if (entry.camera) {
      const msgs::CameraIntrinsics& k = entry.camera->intrinsics;
      text += fmt::format("    camera: fx {} fy {} cx {} cy {}, distortion {} [{}]\n", k.fx, k.fy, k.cx, k.cy,
                          msgs::to_string(entry.camera->distortion.type), fmt::join(entry.camera->distortion.coefficients, ", "));
    }
  }
  return text;
}

}  // namespace

Status update_calibration_entry(const std::string& path, const std::string& sensor,
                                const std::function<void(calib::SensorCalibration&)>& change) {
  calib::Calibration calibration;
  if (std::filesystem::exists(path)) {
    Result<calib::Calibration> existing = calib::load_calibration(path);
    if (!existing) return existing.error();
    calibration = std::move(existing).value();
  }
  auto found = std::find_if(calibration.sensors.begin(), calibration.sensors.end(),
                            [&](const calib::SensorCalibration& entry) { return entry.sensor == sensor; });
  if (found == calibration.sensors.end()) {
    calibration.sensors.push_back(calib::SensorCalibration::from_transform(sensor, SE3()));
    found = std::prev(calibration.sensors.end());
  }
  change(*found);
  return calib::save_calibration(calibration, path);
}

void add_calib_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* calib_command = app.add_subcommand("calib", "Sensor calibration files and procedures");
  calib_command->require_subcommand(1);
  add_calib_motion_command(*calib_command, output, run);
  add_calib_camera_command(*calib_command, output, run);
  add_calib_stereo_command(*calib_command, output, run);
  add_calib_camera_lidar_command(*calib_command, output, run);
  CLI::App* check = calib_command->add_subcommand("check", "Load a calibration YAML and print its summary or its error");
  auto path = std::make_shared<std::string>();
  check->add_option("FILE", *path, "Calibration YAML")->required();
  check->callback([&output, &run, path] {
    run = [&output, path] {
      Result<calib::Calibration> loaded = calib::load_calibration(*path);
      nlohmann::json result = {{"file", *path}, {"kind", "calibration"}};
      if (!loaded) return report_failure(output, result, loaded.error().message);
      result["ok"] = true;
      result["calibration"] = to_json(*loaded);
      return report_success(output, result, to_text(*path, *loaded));
    };
  });
}

}  // namespace hanzo::fusion::app
