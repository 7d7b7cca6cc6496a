// Reading and writing the calibration YAML (layout: calibration.hpp).

#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"
#include "hanzo/fusion/msgs/validate.hpp"

namespace hanzo::fusion::calib {
namespace {

constexpr std::string_view kSuffix = "_to_body";

// Runs a message-level check and reports its failure at the YAML value's file and line.
Status at(const YamlValue& value, Status status) {
  if (status) return status;
  const std::string& message = status.error().message;
  const size_t colon = message.find(": ");
  return value.error(colon == std::string::npos ? message : message.substr(colon + 2));
}

Result<CameraCalibration> parse_intrinsics(const YamlValue& node) {
  HANZO_RETURN_IF_ERROR(node.check_keys({"fx", "fy", "cx", "cy", "width", "height", "distortion_model", "distortion_coeffs"}));
  CameraCalibration camera;
  msgs::CameraIntrinsics& intrinsics = camera.intrinsics;
  HANZO_ASSIGN_OR_RETURN(intrinsics.fx, node["fx"].as_double());
  HANZO_ASSIGN_OR_RETURN(intrinsics.fy, node["fy"].as_double());
  HANZO_ASSIGN_OR_RETURN(intrinsics.cx, node["cx"].as_double());
  HANZO_ASSIGN_OR_RETURN(intrinsics.cy, node["cy"].as_double());
  for (const auto& [key, target] : {std::pair<std::string_view, uint32_t*>{"width", &intrinsics.width}, {"height", &intrinsics.height}}) {
    const YamlValue value = node[key];
    if (!value.present()) continue;
    int64_t pixels = 0;
    HANZO_ASSIGN_OR_RETURN(pixels, value.as_int64());
    if (pixels <= 0 || pixels > 1'000'000) return value.error(fmt::format("expected a positive number of pixels, got {}", pixels));
    *target = static_cast<uint32_t>(pixels);
  }
  if (intrinsics.fx <= 0.0) return node["fx"].error(fmt::format("expected a positive focal length in pixels, got {}", intrinsics.fx));
  if (intrinsics.fy <= 0.0) return node["fy"].error(fmt::format("expected a positive focal length in pixels, got {}", intrinsics.fy));
  HANZO_RETURN_IF_ERROR(at(node["cx"], msgs::validate(intrinsics)));

  const YamlValue model_node = node["distortion_model"];
  if (model_node.present()) {
    std::string model;
    HANZO_ASSIGN_OR_RETURN(model, model_node.as_string());
    const std::optional<msgs::DistortionType> type = msgs::distortion_type_from_string(model);
    if (!type) return model_node.error(fmt::format("expected equidistant, radtan or none, got '{}'", model));
    camera.distortion.type = *type;
  }
  const YamlValue coefficients = node["distortion_coeffs"];
  if (coefficients.present()) {
    HANZO_ASSIGN_OR_RETURN(camera.distortion.coefficients, coefficients.as_doubles());
    if (!model_node.present()) return model_node.error("missing (distortion_coeffs needs a distortion_model: equidistant or radtan)");
  }
  HANZO_RETURN_IF_ERROR(at(coefficients.present() ? coefficients : model_node, msgs::validate(camera.distortion)));
  return camera;
}

Result<SensorCalibration> parse_entry(const std::string& key, const YamlValue& node) {
  if (key.size() <= kSuffix.size() || !key.ends_with(kSuffix)) {
    return node.error("expected an entry named <sensor>_to_body (for example lidar_to_body)");
  }
  SensorCalibration entry;
  entry.sensor = key.substr(0, key.size() - kSuffix.size());
  if (const Result<std::string> word = node.as_string(); word && *word == "identity") return entry;  // mounted at the body origin, no time offset
  if (!node.is_map()) {
    return node.error("expected a map with rotation, translation, time_offset_ns (and intrinsics for cameras), or 'identity'");
  }
  HANZO_RETURN_IF_ERROR(node.check_keys({"rotation", "translation", "time_offset_ns", "intrinsics"}));
  const YamlValue rotation = node["rotation"];
  if (rotation.present()) {
    std::vector<double> wxyz;
    HANZO_ASSIGN_OR_RETURN(wxyz, rotation.as_doubles(4, "(w, x, y, z)"));
    entry.rotation_wxyz = Eigen::Vector4d(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
    const double norm = entry.rotation_wxyz.norm();
    if (std::abs(norm - 1.0) > msgs::kUnitQuaternionTolerance) {
      return rotation.error(fmt::format("expected a unit quaternion (w, x, y, z), got norm {:.6g}", norm));
    }
  }
  const YamlValue translation = node["translation"];
  if (translation.present()) {
    std::vector<double> xyz;
    HANZO_ASSIGN_OR_RETURN(xyz, translation.as_doubles(3, "(x, y, z)"));
    entry.translation = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
  }
  if (node["time_offset_ns"].present()) {
    int64_t offset_ns = 0;
    HANZO_ASSIGN_OR_RETURN(offset_ns, node["time_offset_ns"].as_int64());
    entry.time_offset = Duration::from_nanoseconds(offset_ns);
  }
  if (node["intrinsics"].present()) {
    CameraCalibration camera;
    HANZO_ASSIGN_OR_RETURN(camera, parse_intrinsics(node["intrinsics"]));
    entry.camera = std::move(camera);
  }
  return entry;
}

Result<Calibration> parse(const YamlValue& root) {
  HANZO_RETURN_IF_ERROR(root.check_keys({"calibration"}));
  const YamlValue body = root["calibration"].as_path_root();
  if (!body.present()) return body.error("missing (the file must start with a 'calibration:' map)");
  HANZO_RETURN_IF_ERROR(body.expect_map());
  Calibration calibration;
  for (const auto& [key, node] : body.entries()) {
    SensorCalibration entry;
    HANZO_ASSIGN_OR_RETURN(entry, parse_entry(key, node));
    if (calibration.find(entry.sensor)) return node.error("duplicate entry");
    calibration.sensors.push_back(std::move(entry));
  }
  return calibration;
}

}  // namespace

Result<Calibration> parse_calibration(const std::string& yaml_text, const std::string& source_name) {
  Result<YamlValue> root = YamlValue::load_string(yaml_text, source_name);
  if (!root) return root.error();
  return parse(*root);
}

Result<Calibration> load_calibration(const std::string& path) {
  Result<YamlValue> root = YamlValue::load_file(path);
  if (!root) return root.error();
  return parse(*root);
}

std::string to_yaml(const Calibration& calibration) {
  std::string out = calibration.sensors.empty() ? "calibration: {}\n" : "calibration:\n";
  for (const SensorCalibration& entry : calibration.sensors) {
    out += fmt::format("  {}:\n", yaml::scalar(entry.sensor + std::string(kSuffix)));
    out += fmt::format("    rotation: {}  # quaternion wxyz\n", yaml::flow_sequence(entry.rotation_wxyz));
    out += fmt::format("    translation: {}  # meters\n", yaml::flow_sequence(entry.translation));
    out += fmt::format("    time_offset_ns: {}\n", entry.time_offset.nanoseconds());
    if (!entry.camera) continue;
    const msgs::CameraIntrinsics& intrinsics = entry.camera->intrinsics;
    out += "    intrinsics:\n";
    out += fmt::format("      fx: {}\n      fy: {}\n      cx: {}\n      cy: {}\n", format_double(intrinsics.fx),
                       format_double(intrinsics.fy), format_double(intrinsics.cx), format_double(intrinsics.cy));
    if (intrinsics.width > 0) out += fmt::format("      width: {}\n", intrinsics.width);
    if (intrinsics.height > 0) out += fmt::format("      height: {}\n", intrinsics.height);
    out += fmt::format("      distortion_model: {}\n", msgs::to_string(entry.camera->distortion.type));
    const std::vector<double>& coefficients = entry.camera->distortion.coefficients;
    out += fmt::format("      distortion_coeffs: {}\n",
                       yaml::flow_sequence(Eigen::Map<const Eigen::VectorXd>(coefficients.data(), static_cast<Eigen::Index>(coefficients.size()))));
  }
  return out;
}

Status save_calibration(const Calibration& calibration, const std::string& path) {
  HANZO_RETURN_IF_ERROR(validate(calibration));
  return yaml::write_file_atomically(path, to_yaml(calibration));
}

}  // namespace hanzo::fusion::calib
