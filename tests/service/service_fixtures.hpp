#pragma once
// Shared pieces of the service tests: scratch folders, the PostgreSQL test server's URL, the
// sample recording of examples/data as a message stream, token files.

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <unistd.h>

#include <gtest/gtest.h>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/io/csv_import.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"

namespace hanzo::fusion::testing {

inline std::string read_text(const std::string& path) {
  std::ifstream file(path);
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

/// An empty folder under the system's temporary folder, named after the running test and this
/// process (two checkouts testing at once never share one).
inline std::filesystem::path scratch_dir(const std::string& suffix = "") {
  const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
  std::string name = std::string("hanzo_service_") + info->test_suite_name() + "_" + info->name() + suffix + "_" + std::to_string(::getpid());
  std::replace(name.begin(), name.end(), '/', '_');
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

/// The URL of the PostgreSQL server the ctest fixture started (scripts/test-postgres.sh), or "".
inline std::string postgres_test_url() {
  std::string url = read_text(std::string(HANZO_TEST_POSTGRES_DIR) + "/url");
  while (!url.empty() && (url.back() == '\n' || url.back() == ' ')) url.pop_back();
  return url;
}

struct TimedMessage {
  std::string sensor;
  msgs::SensorMessage message;
};

/// examples/data (IMU 100 Hz, GNSS 5 Hz, wheels 50 Hz, 20 s) merged in time order, as the sensors
/// of examples/data/fusion.yaml.
inline std::vector<TimedMessage> sample_recording() {
  std::vector<TimedMessage> messages;
  for (const char* sensor : {"imu", "gnss", "wheels"}) {
    auto read = io::read_sensor_csv(std::string("examples/data/") + sensor + ".csv");
    EXPECT_TRUE(read.ok()) << (read.ok() ? "" : read.error().message);
    if (!read.ok()) continue;
    for (msgs::SensorMessage& message : read.value()) messages.push_back({sensor, std::move(message)});
  }
  std::stable_sort(messages.begin(), messages.end(), [](const TimedMessage& a, const TimedMessage& b) {
    return msgs::timestamp_of(a.message) < msgs::timestamp_of(b.message);
  });
  return messages;
}

struct Recording {
  std::string config_yaml;
  std::string calibration_yaml;
  std::vector<TimedMessage> messages;
};

/// The IMU and LiDAR of a simulated scenario's first `seconds`.
inline Recording lidar_recording(const std::string& scenario_path, double seconds) {
  sim::Scenario scenario = sim::load_scenario(scenario_path).value();
    std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& s) {
      return s.modality != config::SensorModality::kLidar && s.modality != config::SensorModality::kImu;
    });
  scenario.duration = seconds;
  scenario.num_threads = 0;
  Recording out;
  out.config_yaml = config::to_yaml(sim::scenario_fusion_config(scenario));
  out.calibration_yaml = calib::to_yaml(sim::scenario_calibration(scenario));
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  EXPECT_TRUE(simulation
                  ->run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status {
                    out.messages.push_back({sensor.name, std::move(message)});
                    return ok_status();
                  })
                  .ok());
  return out;
}

/// 12 s of the simulated urban drive: IMU 200 Hz + LiDAR 10 Hz (3 s standing, then driving).
inline const Recording& urban_recording() {
  static const Recording recording = lidar_recording("examples/scenarios/urban_vehicle.yaml", 12.0);
  return recording;
}

inline constexpr const char* kTokensYaml = R"(tokens:
  - name: acme-robot
    organization: acme
    permissions: [fusion:session:write, fusion:session:read, fusion:map:read]
    token: "acme-robot-secret-0001"
  - name: acme-viewer
    organization: acme
    permissions: [fusion:session:read]
    token: "acme-viewer-secret-0002"
  - name: acme-admin
    organization: acme
    permissions: [fusion:admin]
    token: "acme-admin-secret-00003"
  - name: globex-robot
    organization: globex
    permissions: [fusion:session:write, fusion:session:read]
    token: "globex-robot-secret-0004"
  - name: globex-admin
    organization: globex
    permissions: [fusion:admin]
    token: "globex-admin-secret-0005"
  - name: acme-mapper
    organization: acme
    permissions: [fusion:map:read, fusion:map:write]
    token: "acme-mapper-secret-00006"
)";

}  // namespace hanzo::fusion::testing
