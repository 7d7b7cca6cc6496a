// hanzo-fusion sim SCENARIO.yaml --out DIR: runs a simulation scenario and writes
//   DIR/sensors.mcap        the sensor log (every sensor and /ground_truth poses; images as JPEG,
//                           points to 1 mm by default; Foxglove mirrors with --foxglove)
//   DIR/ground_truth.tum    the body trajectory at the scenario's ground_truth_rate
//   DIR/imu_biases.csv      the first IMU's true biases per sample (when there is an IMU)
//   DIR/calibration.yaml    the sensors' extrinsics and camera intrinsics (spec layout)
//   DIR/fusion.yaml         a fusion configuration to run the log
//   DIR/lidar_labels/       with --lidar-labels: each LiDAR sweep's per-point ground truth
//                           (SemanticKITTI .label files) and the class table
// See docs/simulator.md.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "log_writing.hpp"

namespace hanzo::fusion::app {
namespace {

struct SimOptions {
  std::string scenario;
  std::string out;
  std::optional<double> duration;  // absent: the scenario's
  std::optional<int64_t> seed;
  std::optional<int> threads;
  std::string compression = "zstd";
  bool foxglove = false;
  std::string image_compression = "jpeg";
  int jpeg_quality = 90;
  double point_resolution = 0.001;
  std::vector<std::string> sensors;  // empty: all of the scenario's
  bool lidar_labels = false;
};

// Per-point LiDAR ground truth as SemanticKITTI writes it: one little-endian uint32 per point,
// the class id in the low 16 bits, the instance (a moving object's number from 1; 0 for the
// static world) in the high 16 bits; class 0 "unlabelled" (a weather phantom).
class LidarLabelWriter {
 public:
  LidarLabelWriter(const sim::World& world, std::filesystem::path folder) : world_(world), folder_(std::move(folder)) {
    names_.push_back("unlabelled");
    for (int object = -1; object < world.object_count(); ++object) {
      const std::string& name = world.object_class(object);
      if (std::find(names_.begin(), names_.end(), name) == names_.end()) names_.push_back(name);
    }
  }

  Status write(const std::string& sensor, const std::vector<int>& objects) {
    const std::filesystem::path sensor_folder = folder_ / sensor;
    std::error_code error;
    std::filesystem::create_directories(sensor_folder, error);
    if (error) return Error(fmt::format("{}: cannot create the folder ({})", sensor_folder.string(), error.message()));
    std::vector<uint32_t> labels;
    labels.reserve(objects.size());
    const int first_moving = world_.object_count() - static_cast<int>(world_.description().moving_boxes.size());
    for (const int object : objects) {
      const auto name = object == sim::kPhantomReturn ? names_.begin() : std::find(names_.begin(), names_.end(), world_.object_class(object));
      const uint32_t instance = world_.is_moving(object) ? static_cast<uint32_t>(object - first_moving + 1) : 0U;
      labels.push_back((instance << 16U) | static_cast<uint32_t>(name - names_.begin()));
    }
    const std::string path = (sensor_folder / fmt::format("{:06d}.label", sweeps_[sensor]++)).string();
    std::ofstream file(path, std::ios::binary);
    file.write(reinterpret_cast<const char*>(labels.data()), static_cast<std::streamsize>(labels.size() * sizeof(uint32_t)));
    if (!file) return Error(fmt::format("{}: cannot write", path));
    return ok_status();
  }

  // classes.yaml: the class table (id: name) and which ids move.
  Status write_classes() const {
    std::string text = "# The class ids of the .label files (low 16 bits); the high 16 bits number the moving objects from 1.\nclasses:\n";
    for (std::size_t id = 0; id < names_.size(); ++id) text += fmt::format("  {}: {}\n", id, yaml::scalar(names_[id]));
    return yaml::write_file_atomically((folder_ / "classes.yaml").string(), text);
  }

 private:
  const sim::World& world_;
  std::filesystem::path folder_;
  std::vector<std::string> names_;
  std::map<std::string, int> sweeps_;
};

io::Trajectory ground_truth(const sim::ScenarioSimulation& simulation) {
  io::Trajectory trajectory;
  const double rate = simulation.scenario().ground_truth_rate_hz;
  const Timestamp start = simulation.scenario().start_time;
  const Timestamp log_start = sim::scenario_log_start_time(simulation.scenario());
  for (int64_t k = 0;; ++k) {
    const Timestamp time = start + Duration::from_nanoseconds(std::llround(static_cast<double>(k) * 1e9 / rate));
    if (time > simulation.end_time()) break;
    if (time < log_start) continue;
    trajectory.timestamps.push_back(time);
    trajectory.poses.push_back(simulation.trajectory().sample(time).T_world_body.matrix());
  }
  return trajectory;
}

std::string bias_csv(const std::vector<sim::ImuBiasTruth>& biases) {
  std::string text = "timestamp_ns,accel_bias_x,accel_bias_y,accel_bias_z,gyro_bias_x,gyro_bias_y,gyro_bias_z\n";
  for (const sim::ImuBiasTruth& bias : biases) {
    text += fmt::format("{},{},{},{},{},{},{}\n", bias.timestamp.nanoseconds(), format_double(bias.accel_bias.x()),
                        format_double(bias.accel_bias.y()), format_double(bias.accel_bias.z()), format_double(bias.gyro_bias.x()),
                        format_double(bias.gyro_bias.y()), format_double(bias.gyro_bias.z()));
  }
  return text;
}

int run_sim(const Output& output, const SimOptions& options) {
  nlohmann::json result = {{"scenario", options.scenario}, {"out", options.out}};
  if (options.duration && !(*options.duration > 0.0 && std::isfinite(*options.duration))) {
    return report_failure(output, result, fmt::format("--duration: expected seconds > 0, got {}", *options.duration));
  }
  if (options.seed && *options.seed < 0) return report_failure(output, result, fmt::format("--seed: expected >= 0, got {}", *options.seed));
  Result<sim::Scenario> scenario = sim::load_scenario(options.scenario);
  if (!scenario) return report_failure(output, result, scenario.error().message);
  if (options.duration) scenario->duration = *options.duration;
  if (options.seed) sim::set_seed(*scenario, static_cast<uint64_t>(*options.seed));
  if (options.threads) scenario->num_threads = *options.threads;
  for (const std::string& name : options.sensors) {
    const bool known = std::any_of(scenario->sensors.begin(), scenario->sensors.end(), [&](const sim::ScenarioSensor& s) { return s.name == name; });
    if (!known) return report_failure(output, result, fmt::format("--sensors: the scenario has no sensor '{}'", name));
  }
  if (!options.sensors.empty()) {
    std::erase_if(scenario->sensors, [&](const sim::ScenarioSensor& s) {
      return std::find(options.sensors.begin(), options.sensors.end(), s.name) == options.sensors.end();
    });
  }
  Result<std::unique_ptr<sim::ScenarioSimulation>> simulation = sim::ScenarioSimulation::create(std::move(*scenario));
  if (!simulation) return report_failure(output, result, simulation.error().message);
  sim::ScenarioSimulation& run = **simulation;
  std::error_code ec;
  std::filesystem::create_directories(options.out, ec);
  if (ec) return report_failure(output, result, fmt::format("{}: cannot create the folder ({})", options.out, ec.message()));

  const std::filesystem::path folder(options.out);
  const std::string log_path = (folder / "sensors.mcap").string();
  const io::Trajectory truth = ground_truth(run);
  std::optional<LidarLabelWriter> labels;
  if (options.lidar_labels) labels.emplace(run.world(), folder / "lidar_labels");
  const int code = write_log(output, result, {log_path, options.compression, options.foxglove, options.image_compression,
                                                           options.jpeg_quality, options.point_resolution, nullptr}, [&](io::SensorLogWriter& writer) -> Status {
    const GeodeticPoint& datum = run.scenario().datum;
    HANZO_RETURN_IF_ERROR(writer.add_metadata({"hanzo.simulation",
                                               {{"scenario", run.scenario().name},
                                                {"seed", std::to_string(run.scenario().seed)},
                                                {"scenario_file", options.scenario},
                                                {"datum_latitude", format_double(datum.latitude_deg)},
                                                {"datum_longitude", format_double(datum.longitude_deg)},
                                                {"datum_altitude", format_double(datum.altitude_m)}}}));
    // The ground truth goes into the log too (/ground_truth, with its Foxglove mirror), each
    // pose before the first sensor message after it, so the log stays in time order.
    std::size_t next_truth = 0;
    auto write_truth_until = [&](Timestamp time) -> Status {
      for (; next_truth < truth.size() && truth.timestamps[next_truth] <= time; ++next_truth) {
        const Timestamp stamp = truth.timestamps[next_truth];
        const sim::TrajectorySample sample = run.trajectory().sample(stamp);
        msgs::PoseEstimate pose;
        pose.timestamp = stamp;
        pose.frame_id = "world";
        pose.child_frame_id = "body";
        pose.T_world_body = msgs::Pose::from_se3(sample.T_world_body);
        pose.velocity = sample.velocity_world;
        HANZO_RETURN_IF_ERROR(writer.write("/ground_truth", pose));
      }
      return ok_status();
    };
    const Status simulated = run.run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status {
      HANZO_RETURN_IF_ERROR(write_truth_until(msgs::timestamp_of(message)));
      if (labels && std::holds_alternative<msgs::PointCloudMessage>(message)) {
        HANZO_RETURN_IF_ERROR(labels->write(sensor.name, run.lidar_object_ids(sensor.name)));
      }
      // A camera's ground-truth detections on its topic + "/detections" (what `run` reads).
      const bool detections = std::holds_alternative<msgs::DetectionsMessage>(message);
      return writer.write(detections ? sensor.topic + std::string(config::kDetectionsTopicSuffix) : sensor.topic, message, sensor.name);
    });
    if (!simulated) return simulated;
    return write_truth_until(run.end_time());
  });
  if (code != 0) return code;

  const std::string truth_path = (folder / "ground_truth.tum").string();
  const std::string calibration_path = (folder / "calibration.yaml").string();
  const std::string config_path = (folder / "fusion.yaml").string();
  if (Status written = io::write_trajectory(truth_path, truth, io::TrajectoryFormat::kTum); !written) {
    return report_failure(output, result, written.error().message);
  }
  if (Status written = calib::save_calibration(sim::scenario_calibration(run.scenario()), calibration_path); !written) {
    return report_failure(output, result, written.error().message);
  }
  if (Status written = config::save_fusion_config(sim::scenario_fusion_config(run.scenario()), config_path); !written) {
    return report_failure(output, result, written.error().message);
  }
  nlohmann::json files = {{"log", log_path}, {"ground_truth", truth_path}, {"calibration", calibration_path}, {"fusion_config", config_path}};
  if (labels) {
    if (Status written = labels->write_classes(); !written) return report_failure(output, result, written.error().message);
    files["lidar_labels"] = (folder / "lidar_labels").string();
  }
  if (!run.imu_bias_truth().empty()) {
    const std::string bias_path = (folder / "imu_biases.csv").string();
    if (Status written = yaml::write_file_atomically(bias_path, bias_csv(run.imu_bias_truth())); !written) {
      return report_failure(output, result, written.error().message);
    }
    files["imu_biases"] = bias_path;
  }

  const double duration = (run.end_time() - run.scenario().start_time).seconds();
  std::string text = fmt::format("Simulated '{}' ({:.1f} s, seed {}) into {}\n  {:<14} {:>15} {:>9} {:>14} {:>10}\n",
                                 run.scenario().name, duration, run.scenario().seed, options.out, "sensor", "modality",
                                 "messages", "elements", "time (s)");
  nlohmann::json sensors = nlohmann::json::array();
  double total_seconds = 0.0;
  for (const sim::SensorRunStatistics& sensor : run.statistics()) {
    sensors.push_back({{"name", sensor.name}, {"modality", sensor.modality}, {"messages", sensor.messages},
                       {"skipped", sensor.skipped}, {"elements", sensor.elements}, {"simulation_seconds", sensor.simulation_seconds}});
    text += fmt::format("  {:<14} {:>15} {:>9} {:>14} {:>10.2f}\n", sensor.name, sensor.modality, sensor.messages, sensor.elements,
                        sensor.simulation_seconds);
    total_seconds += sensor.simulation_seconds;
  }
  text += fmt::format("  ground truth: {} poses; files: sensors.mcap ground_truth.tum calibration.yaml fusion.yaml{}{}\n", truth.size(),
                      run.imu_bias_truth().empty() ? "" : " imu_biases.csv", labels ? " lidar_labels/" : "");
  result["ok"] = true;
  result["name"] = run.scenario().name;
  result["seed"] = run.scenario().seed;
  result["duration_s"] = duration;
  result["datum"] = {{"latitude", run.scenario().datum.latitude_deg}, {"longitude", run.scenario().datum.longitude_deg},
                     {"altitude", run.scenario().datum.altitude_m}};
  result["sensors"] = sensors;
  result["simulation_seconds"] = total_seconds;
  result["ground_truth_poses"] = truth.size();
  result["files"] = files;
  return report_success(output, result, text);
}

}  // namespace

void add_sim_command(CLI::App& app, const Output& output, Command& run) {
  auto options = std::make_shared<SimOptions>();
  CLI::App* command = app.add_subcommand("sim", "Simulate a scenario: sensor log, ground truth, calibration, fusion config");
  command->add_option("SCENARIO", options->scenario, "Scenario YAML (see examples/scenarios/)")->required();
  command->add_option("--out", options->out, "Output folder (created when missing)")->required();
  command->add_option("--duration", options->duration, "Seconds to simulate (default: the scenario's)");
  command->add_option("--seed", options->seed, "Override the scenario's seed (>= 0)");
  command->add_option("--threads", options->threads, "Ray-casting threads for LiDARs and cameras (0: all cores; same output)")
      ->check(CLI::Range(0, 1024));
  command->add_option("--compression", options->compression, "Chunk compression: zstd, lz4 or none")->capture_default_str();
  command->add_flag("--foxglove,!--no-foxglove", options->foxglove,
                    "Also write Foxglove mirror channels (PointCloud, CompressedImage, ...; about doubles the LiDAR's share)");
  command->add_option("--image-compression", options->image_compression, "Camera images stored as jpeg, png or none (raw)")
      ->check(CLI::IsMember({"jpeg", "png", "none"}))
      ->capture_default_str();
  command->add_option("--jpeg-quality", options->jpeg_quality, "JPEG quality (1..100)")->check(CLI::Range(1, 100))->capture_default_str();
  command->add_option("--point-resolution", options->point_resolution,
                      "LiDAR points stored as multiples of this many meters (0: exact floats)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  command->add_option("--sensors", options->sensors, "Simulate only these sensors (names from the scenario, comma-separated)")
      ->delimiter(',');
  command->add_flag("--lidar-labels", options->lidar_labels,
                    "Also write each LiDAR sweep's per-point ground truth (lidar_labels/SENSOR/NNNNNN.label, SemanticKITTI format, and classes.yaml)");
  command->callback([&output, &run, options] { run = [&output, options] { return run_sim(output, *options); }; });
}

}  // namespace hanzo::fusion::app
