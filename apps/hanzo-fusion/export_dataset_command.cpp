// hanzo-fusion export dataset LOG --trajectory FILE --calib CALIB --out DIR [--layout kitti|nuscenes]:
// synchronized sweeps and images with trajectory poses as training data (io/dataset_export.hpp);
// docs/sensor-logs.md.

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/io/dataset_export.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::app {
namespace {

struct DatasetOptions {
  std::string log;
  std::string out;
  std::string trajectory;
  std::string trajectory_format = "tum";
  std::string calibration;
  std::string config;
  std::string layout = "kitti";
  std::vector<std::string> sensors;
  std::string reference;
  int every = 1;
  double max_time_difference = 0.05;
  double max_trajectory_gap = 0.5;
  bool no_deskew = false;
  bool keep_incomplete = false;
  std::string scene = "scene-0001";
};

// The LiDARs and cameras to export: from the fusion configuration's sensors (with --config),
// else from the log's channels (their "sensor" and "modality" metadata); --sensors picks some.
Result<std::vector<io::DatasetSensor>> dataset_sensors(const DatasetOptions& options) {
  std::vector<io::DatasetSensor> found;
  if (!options.config.empty()) {
    config::FusionConfig configuration;
    HANZO_ASSIGN_OR_RETURN(configuration, config::load_fusion_config(options.config));
    for (const config::SensorConfig& sensor : configuration.sensors) {
      const bool camera = sensor.modality == config::SensorModality::kCamera;
      if (camera || sensor.modality == config::SensorModality::kLidar) found.push_back({sensor.name, sensor.topic, camera});
    }
  } else {
    std::unique_ptr<io::SensorLogReader> reader;
    HANZO_ASSIGN_OR_RETURN(reader, io::SensorLogReader::open(options.log));
    for (const auto& [id, channel] : reader->mcap().channels()) {
      const auto modality = channel.metadata.find("modality");
      const auto sensor = channel.metadata.find("sensor");
      if (modality == channel.metadata.end() || sensor == channel.metadata.end()) continue;
      if (modality->second == "point_cloud" || modality->second == "image") found.push_back({sensor->second, channel.topic, modality->second == "image"});
    }
  }
  if (options.sensors.empty()) {
    if (found.empty()) return Error(fmt::format("{}: no LiDAR or camera to export", options.config.empty() ? options.log : options.config));
    return found;
  }
  std::vector<io::DatasetSensor> picked;
  for (const std::string& name : options.sensors) {
    const auto match = std::find_if(found.begin(), found.end(), [&](const io::DatasetSensor& s) { return s.name == name; });
    if (match == found.end()) {
      std::string known;
      for (const io::DatasetSensor& s : found) known += (known.empty() ? "" : ", ") + s.name;
      return Error(fmt::format("--sensors: no LiDAR or camera '{}' (there are: {})", name, known.empty() ? "none" : known));
    }
    picked.push_back(*match);
  }
  return picked;
}

int run_export_dataset(const Output& output, const DatasetOptions& options) {
  nlohmann::json result = {{"format", "dataset"}, {"layout", options.layout}, {"out", options.out}, {"log", options.log}};
  io::DatasetExportConfig config;
  Result<io::DatasetLayout> layout = io::dataset_layout_from_name(options.layout);
  if (!layout) return report_failure(output, result, "--layout: " + layout.error().message);
  config.layout = *layout;
  config.reference_sensor = options.reference;
  config.every = options.every;
  config.max_time_difference_s = options.max_time_difference;
  config.max_trajectory_gap_s = options.max_trajectory_gap;
  config.deskew = !options.no_deskew;
  config.require_all_sensors = !options.keep_incomplete;
  config.scene_name = options.scene;
  Result<std::vector<io::DatasetSensor>> sensors = dataset_sensors(options);
  if (!sensors) return report_failure(output, result, sensors.error().message);
  config.sensors = std::move(*sensors);
  Result<io::TrajectoryFormat> format = io::trajectory_format_from_name(options.trajectory_format);
  if (!format) return report_failure(output, result, "--trajectory-format: " + format.error().message);
  Result<io::Trajectory> trajectory = io::read_trajectory(options.trajectory, *format);
  if (!trajectory) return report_failure(output, result, trajectory.error().message);
  Result<calib::Calibration> calibration = calib::load_calibration(options.calibration);
  if (!calibration) return report_failure(output, result, calibration.error().message);
  Result<io::DatasetExportSummary> summary = io::export_dataset(options.log, *trajectory, *calibration, options.out, config);
  if (!summary) return report_failure(output, result, summary.error().message);
  nlohmann::json sensor_list = nlohmann::json::array();
  for (const io::DatasetSensor& sensor : config.sensors) sensor_list.push_back({{"name", sensor.name}, {"topic", sensor.topic}, {"camera", sensor.is_camera}});
  result["ok"] = true;
  result["sensors"] = sensor_list;
  result["frames"] = summary->frames;
  result["reference_messages"] = summary->reference_messages;
  result["left_out_outside_trajectory"] = summary->outside_trajectory;
  result["left_out_missing_sensor"] = summary->missing_sensor;
  result["deskewed_sweeps"] = summary->deskewed_sweeps;
  result["undistorted_images"] = summary->undistorted_images;
  result["files_by_sensor"] = summary->files_by_sensor;
  result["bytes_written"] = summary->bytes_written;
  result["first_frame_time_s"] = summary->first_frame_time_s;
  result["last_frame_time_s"] = summary->last_frame_time_s;
  std::string text = fmt::format("{}: {} frames ({} layout) from {} messages of the reference sensor, {:.1f} MB\n", options.out, summary->frames,
                                 options.layout, summary->reference_messages, summary->bytes_written / 1e6);
  for (const auto& [sensor, count] : summary->files_by_sensor) text += fmt::format("  {}: {} files\n", sensor, count);
  if (summary->outside_trajectory > 0) text += fmt::format("  left out: {} frames outside the trajectory\n", summary->outside_trajectory);
  if (summary->missing_sensor > 0) {
    text += fmt::format("  left out: {} frames without another sensor's message within {} s\n", summary->missing_sensor, options.max_time_difference);
  }
  if (summary->deskewed_sweeps > 0) text += fmt::format("  deskewed {} sweeps with the trajectory\n", summary->deskewed_sweeps);
  if (summary->undistorted_images > 0) text += fmt::format("  undistorted {} images\n", summary->undistorted_images);
  return report_success(output, result, text);
}

}  // namespace

void add_export_dataset_command(CLI::App& export_app, const Output& output, Command& run) {
  auto dataset_options = std::make_shared<DatasetOptions>();
  CLI::App* dataset = export_app.add_subcommand(
      "dataset", "LiDAR sweeps and camera images with trajectory poses and calibration as training data (KITTI or nuScenes layout)");
  dataset->add_option("log", dataset_options->log, "Sensor log (MCAP)")->required();
  dataset->add_option("--trajectory", dataset_options->trajectory, "Poses of the body (e.g. a run's trajectory_optimized.tum)")->required();
  dataset->add_option("--trajectory-format", dataset_options->trajectory_format, "tum, kitti or euroc")->capture_default_str();
  dataset->add_option("--calib", dataset_options->calibration, "Calibration: T_body_sensor, time offsets, camera intrinsics")->required();
  dataset->add_option("--out", dataset_options->out, "Folder to create (must not exist or be empty)")->required();
  dataset->add_option("--layout", dataset_options->layout, "kitti (KITTI odometry) or nuscenes (nuScenes tables)")->capture_default_str();
  dataset->add_option("--config", dataset_options->config, "Fusion configuration: its LiDARs and cameras and their topics (default: the log's channels)");
  dataset->add_option("--sensors", dataset_options->sensors, "Only these sensors (comma-separated names)")->delimiter(',');
  dataset->add_option("--reference", dataset_options->reference, "Sensor whose messages make the frames (default: the first LiDAR, else the first camera)");
  dataset->add_option("--every", dataset_options->every, "Every N-th message of the reference sensor")->capture_default_str()->check(CLI::PositiveNumber);
  dataset->add_option("--max-time-difference", dataset_options->max_time_difference,
                      "Seconds another sensor's message may be from the frame's time")->capture_default_str();
  dataset->add_option("--max-trajectory-gap", dataset_options->max_trajectory_gap,
                      "Seconds between the trajectory poses around a frame, at most")->capture_default_str();
  dataset->add_flag("--no-deskew", dataset_options->no_deskew, "Keep sweeps as recorded (default: deskewed with the trajectory when points have times)");
  dataset->add_flag("--keep-incomplete", dataset_options->keep_incomplete, "nuscenes: keep frames missing a sensor's message");
  dataset->add_option("--scene", dataset_options->scene, "nuscenes: scene and log name")->capture_default_str();
  dataset->callback([&output, &run, dataset_options] { run = [&output, dataset_options] { return run_export_dataset(output, *dataset_options); }; });
}

}  // namespace hanzo::fusion::app
