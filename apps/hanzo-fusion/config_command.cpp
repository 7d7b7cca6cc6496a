// hanzo-fusion config check FILE: loads a fusion configuration and prints its summary.

#include <memory>
#include <string>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"

namespace hanzo::fusion::app {
namespace {

nlohmann::json vector_json(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

nlohmann::json to_json(const config::FusionConfig& cfg) {
  const config::CovarianceConfig& c = cfg.frontend.covariance;
  nlohmann::json sensors = nlohmann::json::array();
  for (const config::SensorConfig& sensor : cfg.sensors) {
    sensors.push_back({{"name", sensor.name},
                       {"modality", config::to_string(sensor.modality)},
                       {"topic", sensor.topic},
                       {"rate_hz", sensor.rate_hz},
                       {"body_frame", sensor.body_frame},
                       {"type", sensor.type}});
  }
  return {{"frontend",
           {{"type", config::to_string(cfg.frontend.type)},
            {"predict_rate_hz", cfg.frontend.predict_rate_hz},
            {"covariance",
             {{"initial_position", vector_json(c.initial_position)},
              {"initial_orientation", vector_json(c.initial_orientation)},
              {"initial_velocity", vector_json(c.initial_velocity)},
              {"process_noise_accel", c.process_noise_accel},
              {"process_noise_gyro", c.process_noise_gyro},
              {"accel_bias_random_walk", c.accel_bias_random_walk},
              {"gyro_bias_random_walk", c.gyro_bias_random_walk}}}}},
          {"sensors", sensors}};
}

std::string to_text(const std::string& path, const config::FusionConfig& cfg) {
  const config::CovarianceConfig& c = cfg.frontend.covariance;
  std::string text = fmt::format("{}: valid fusion configuration\n", path);
  text += fmt::format("  frontend: {} at {} Hz\n", config::to_string(cfg.frontend.type), cfg.frontend.predict_rate_hz);
  text += fmt::format("  initial sigma: position [{}] m, orientation [{}] rad, velocity [{}] m/s\n",
                      fmt::join(c.initial_position, ", "), fmt::join(c.initial_orientation, ", "),
                      fmt::join(c.initial_velocity, ", "));
  text += fmt::format("  IMU noise: accel {} m/s^2, gyro {} rad/s; bias random walk: accel {} m/s^2/sqrt(Hz), gyro {} rad/s/sqrt(Hz)\n",
                      c.process_noise_accel, c.process_noise_gyro, c.accel_bias_random_walk, c.gyro_bias_random_walk);
  text += fmt::format("  sensors ({}):\n", cfg.sensors.size());
  text += fmt::format("    {:<16} {:<15} {:<26} {:>8}  {:<20} {}\n", "name", "modality", "topic", "rate Hz", "body_frame", "type");
  for (const config::SensorConfig& s : cfg.sensors) {
    text += fmt::format("    {:<16} {:<15} {:<26} {:>8}  {:<20} {}\n", s.name, config::to_string(s.modality), s.topic, s.rate_hz,
                        s.body_frame, s.type.empty() ? "-" : s.type);
  }
  return text;
}

}  // namespace

void add_config_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* config_command = app.add_subcommand("config", "Fusion configuration files");
  config_command->require_subcommand(1);
  CLI::App* check = config_command->add_subcommand("check", "Load a fusion configuration YAML and print its summary or its error");
  auto path = std::make_shared<std::string>();
  check->add_option("FILE", *path, "Fusion configuration YAML")->required();
  check->callback([&output, &run, path] {
    run = [&output, path] {
      Result<config::FusionConfig> loaded = config::load_fusion_config(*path);
      nlohmann::json result = {{"file", *path}, {"kind", "fusion_config"}};
      if (!loaded) return report_failure(output, result, loaded.error().message);
      result["ok"] = true;
      result["config"] = to_json(*loaded);
      return report_success(output, result, to_text(*path, *loaded));
    };
  });
}

}  // namespace hanzo::fusion::app
