// Reading and writing the fusion configuration YAML (layout: fusion_config.hpp).

#include <filesystem>
#include <fstream>
#include <set>

#include <fmt/format.h>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"

namespace hanzo::fusion::config {
namespace {


Result<double> positive_rate(const YamlValue& value) {
  Result<double> rate = value.as_double();
  if (!rate) return rate;
  if (*rate <= 0.0) return value.error(fmt::format("expected a positive rate in Hz, got {}", *rate));
  return rate;
}

Result<CovarianceConfig> parse_covariance(const YamlValue& node) {
  CovarianceConfig covariance;
  if (!node.present()) return covariance;
  HANZO_RETURN_IF_ERROR(node.check_keys({"initial_position", "initial_orientation", "initial_velocity", "process_noise_accel",
                                  "process_noise_gyro", "accel_bias_random_walk", "gyro_bias_random_walk"}));
  HANZO_ASSIGN_OR_RETURN(covariance.initial_position, yaml::vector3_or(node["initial_position"], covariance.initial_position, "(x, y, z)"));
  HANZO_ASSIGN_OR_RETURN(covariance.initial_orientation,
                 yaml::vector3_or(node["initial_orientation"], covariance.initial_orientation, "(roll, pitch, yaw)"));
  HANZO_ASSIGN_OR_RETURN(covariance.initial_velocity, yaml::vector3_or(node["initial_velocity"], covariance.initial_velocity, "(x, y, z)"));
  HANZO_ASSIGN_OR_RETURN(covariance.process_noise_accel, yaml::non_negative_or(node["process_noise_accel"], covariance.process_noise_accel));
  HANZO_ASSIGN_OR_RETURN(covariance.process_noise_gyro, yaml::non_negative_or(node["process_noise_gyro"], covariance.process_noise_gyro));
  HANZO_ASSIGN_OR_RETURN(covariance.accel_bias_random_walk,
                 yaml::non_negative_or(node["accel_bias_random_walk"], covariance.accel_bias_random_walk));
  HANZO_ASSIGN_OR_RETURN(covariance.gyro_bias_random_walk, yaml::non_negative_or(node["gyro_bias_random_walk"], covariance.gyro_bias_random_walk));
  return covariance;
}

Result<FrontendConfig> parse_frontend(const YamlValue& node) {
  FrontendConfig frontend;
  if (!node.present()) return frontend;
  HANZO_RETURN_IF_ERROR(node.check_keys({"type", "predict_rate", "covariance"}));
  if (node["type"].present()) {
    Result<std::string> name = node["type"].as_string();
    if (!name) return name.error();
    const std::optional<FrontendType> type = frontend_type_from_string(*name);
    if (!type) return node["type"].error(fmt::format("expected ekf, ukf or particle, got '{}'", *name));
    frontend.type = *type;
  }
  if (node["predict_rate"].present()) HANZO_ASSIGN_OR_RETURN(frontend.predict_rate_hz, positive_rate(node["predict_rate"]));
  HANZO_ASSIGN_OR_RETURN(frontend.covariance, parse_covariance(node["covariance"]));
  return frontend;
}

Result<SensorConfig> parse_sensor(const std::string& name, const YamlValue& node) {
  SensorConfig sensor;
  sensor.name = name;
  if (!node.is_map()) return node.error("expected a map with topic, rate, body_frame (and optionally type, modality)");
  HANZO_RETURN_IF_ERROR(node.check_keys({"topic", "rate", "body_frame", "type", "modality"}));
  const std::optional<SensorModality> inferred = infer_modality(name);
  if (node["modality"].present()) {
    Result<std::string> text = node["modality"].as_string();
    if (!text) return text.error();
    const std::optional<SensorModality> modality = sensor_modality_from_string(*text);
    if (!modality) return node["modality"].error(fmt::format("expected imu, lidar, camera, gnss, wheel_odometry or radar, got '{}'", *text));
    sensor.modality = *modality;
  } else if (inferred) {
    sensor.modality = *inferred;
  } else {
    return node.error("cannot tell the sensor's modality from its name; add 'modality: imu|lidar|camera|gnss|wheel_odometry|radar'");
  }
  sensor.topic = "/sensors/" + name;
  if (node["topic"].present()) HANZO_ASSIGN_OR_RETURN(sensor.topic, node["topic"].as_string());
  if (sensor.topic.empty()) return node["topic"].error("expected a topic name, got an empty string");
  if (!node["rate"].present()) return node["rate"].error("missing (expected the sensor's rate in Hz)");
  HANZO_ASSIGN_OR_RETURN(sensor.rate_hz, positive_rate(node["rate"]));
  sensor.body_frame = name + "_link";
  if (node["body_frame"].present()) HANZO_ASSIGN_OR_RETURN(sensor.body_frame, node["body_frame"].as_string());
  if (sensor.body_frame.empty()) return node["body_frame"].error("expected a frame name, got an empty string");
  if (node["type"].present()) HANZO_ASSIGN_OR_RETURN(sensor.type, node["type"].as_string());
  return sensor;
}

Result<FusionConfig> parse(const YamlValue& root) {
  HANZO_RETURN_IF_ERROR(root.check_keys({"fusion"}));
  const YamlValue fusion = root["fusion"].as_path_root();
  if (!fusion.present()) return fusion.error("missing (the file must start with a 'fusion:' map)");
  HANZO_RETURN_IF_ERROR(fusion.check_keys({"frontend", "sensors"}));
  FusionConfig config;
  HANZO_ASSIGN_OR_RETURN(config.frontend, parse_frontend(fusion["frontend"]));
  const YamlValue sensors = fusion["sensors"];
  HANZO_RETURN_IF_ERROR(sensors.expect_map());
  std::set<std::string> topics;
  for (const auto& [name, node] : sensors.entries()) {
    if (config.find_sensor(name)) return node.error("duplicate sensor name");
    Result<SensorConfig> sensor = parse_sensor(name, node);
    if (!sensor) return sensor.error();
    if (!topics.insert(sensor->topic).second) {
      return node["topic"].error(fmt::format("topic '{}' is already used by another sensor", sensor->topic));
    }
    config.sensors.push_back(std::move(sensor).value());
  }
  return config;
}

}  // namespace

Result<FusionConfig> parse_fusion_config(const std::string& yaml_text, const std::string& source_name) {
  Result<YamlValue> root = YamlValue::load_string(yaml_text, source_name);
  if (!root) return root.error();
  return parse(*root);
}

Result<FusionConfig> load_fusion_config(const std::string& path) {
  Result<YamlValue> root = YamlValue::load_file(path);
  if (!root) return root.error();
  return parse(*root);
}

std::string to_yaml(const FusionConfig& config) {
  const CovarianceConfig& c = config.frontend.covariance;
  std::string out = "fusion:\n  frontend:\n";
  out += fmt::format("    type: {}  # ekf | ukf | particle\n", to_string(config.frontend.type));
  out += fmt::format("    predict_rate: {}  # Hz, IMU propagation rate\n", format_double(config.frontend.predict_rate_hz));
  out += "    covariance:\n";
  out += fmt::format("      initial_position: {}  # meters, diagonal\n", yaml::flow_sequence(c.initial_position));
  out += fmt::format("      initial_orientation: {}  # radians, diagonal\n", yaml::flow_sequence(c.initial_orientation));
  out += fmt::format("      initial_velocity: {}  # m/s, diagonal\n", yaml::flow_sequence(c.initial_velocity));
  out += fmt::format("      process_noise_accel: {}  # m/s^2\n", format_double(c.process_noise_accel));
  out += fmt::format("      process_noise_gyro: {}  # rad/s\n", format_double(c.process_noise_gyro));
  out += fmt::format("      accel_bias_random_walk: {}  # m/s^2/sqrt(Hz)\n", format_double(c.accel_bias_random_walk));
  out += fmt::format("      gyro_bias_random_walk: {}  # rad/s/sqrt(Hz)\n", format_double(c.gyro_bias_random_walk));
  out += config.sensors.empty() ? "  sensors: {}\n" : "  sensors:\n";
  for (const SensorConfig& sensor : config.sensors) {
    out += fmt::format("    {}:\n", yaml::scalar(sensor.name));
    if (infer_modality(sensor.name) != sensor.modality) out += fmt::format("      modality: {}\n", to_string(sensor.modality));
    out += fmt::format("      topic: {}\n", yaml::scalar(sensor.topic));
    out += fmt::format("      rate: {}  # Hz\n", format_double(sensor.rate_hz));
    out += fmt::format("      body_frame: {}\n", yaml::scalar(sensor.body_frame));
    if (!sensor.type.empty()) out += fmt::format("      type: {}\n", yaml::scalar(sensor.type));
  }
  return out;
}

Status save_fusion_config(const FusionConfig& config, const std::string& path) {
  if (Status status = validate(config); !status) return status;
  return yaml::write_file_atomically(path, to_yaml(config));
}

}  // namespace hanzo::fusion::config
