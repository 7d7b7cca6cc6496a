// hanzo-fusion map build --log LOG --trajectory POSES --out MAP.fmap: mapping with known poses.
// Every point cloud of the chosen topic is placed with the trajectory's pose at its time
// (interpolated on SE3) composed with the sensor's extrinsics from the calibration, and
// integrated into the selected layers (2D or 3D occupancy, point map). The map's provenance
// records both input files with their SHA-256 and the options used.

#include <algorithm>
#include <chrono>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/maps/map_builder.hpp"
#include "hanzo/fusion/maps/map_store.hpp"
#include "hanzo/fusion/maps/provenance.hpp"
#include "map_commands.hpp"

namespace hanzo::fusion::app {
namespace {

/// T_world_body at `time` by SE3 interpolation, or nothing outside the trajectory's span.
std::optional<SE3> pose_at(const io::Trajectory& trajectory, Timestamp time) {
  const auto& times = trajectory.timestamps;
  if (trajectory.empty() || time < times.front() || time > times.back()) return std::nullopt;
  const auto upper = std::lower_bound(times.begin(), times.end(), time);
  const std::size_t i = static_cast<std::size_t>(upper - times.begin());
  if (*upper == time) return trajectory.pose_se3(i);
  const double fraction = (time - times[i - 1]).seconds() / (times[i] - times[i - 1]).seconds();
  return SE3::interpolate(trajectory.pose_se3(i - 1), trajectory.pose_se3(i), fraction);
}

std::string options_yaml(const MapBuildOptions& options) {
  return fmt::format("topic: {}\noccupancy: {}\nresolution: {}\nheight_band: [{}, {}]\npoints_voxel: {}\ntsdf_voxel: {}\nmax_range: {}\n",
                     options.topic, options.occupancy, options.resolution, options.height_band[0], options.height_band[1],
                     options.points_voxel, options.tsdf_voxel, options.max_range) +
         (options.keep_moving_points ? "keep_moving_points: true\n" : "");
}

Result<nlohmann::json> build(const MapBuildOptions& options) {
  if (options.height_band.size() != 2) {
    return Error{fmt::format("--height-band: expected 2 values min,max (m), got {}", options.height_band.size())};
  }
  maps::MapBuilderConfig config;
  config.occupancy_2d = options.occupancy == "2d";
  config.occupancy_3d = options.occupancy == "3d";
  if (!config.occupancy_2d && !config.occupancy_3d && options.occupancy != "none") {
    return Error{fmt::format("--occupancy: expected 2d, 3d or none, got '{}'", options.occupancy)};
  }
  config.occupancy_2d_config.resolution = options.resolution;
  config.occupancy_2d_config.max_range = options.max_range;
  config.occupancy_3d_config.resolution = options.resolution;
  config.occupancy_3d_config.max_range = options.max_range;
  config.min_height = options.height_band[0];
  config.max_height = options.height_band[1];
  config.points = options.points_voxel > 0.0;
  config.point_map.voxel_size = options.points_voxel > 0.0 ? options.points_voxel : 0.1;
  config.point_map.moving_points.enabled = !options.keep_moving_points;
  config.tsdf = options.tsdf_voxel > 0.0;
  config.tsdf_config.voxel_size = options.tsdf_voxel > 0.0 ? options.tsdf_voxel : 0.05;
  config.tsdf_config.max_range = options.max_range;
  auto created = maps::MapBuilder::create(config);
  if (!created) return created.error();
  maps::MapBuilder& builder = *created;

  io::TrajectoryFormat format = io::TrajectoryFormat::kTum;
  HANZO_ASSIGN_OR_RETURN(format, io::trajectory_format_from_name(options.trajectory_format));
  io::Trajectory trajectory;
  HANZO_ASSIGN_OR_RETURN(trajectory, io::read_trajectory(options.trajectory, format));
  SE3 T_body_sensor;
  const std::string sensor = options.sensor.empty() ? options.topic.substr(options.topic.rfind('/') + 1) : options.sensor;
  if (!options.calibration.empty()) {
    calib::Calibration calibration;
    HANZO_ASSIGN_OR_RETURN(calibration, calib::load_calibration(options.calibration));
    const calib::SensorCalibration* entry = calibration.find(sensor);
    if (entry == nullptr) return Error{fmt::format("{}: no extrinsics for sensor '{}'", options.calibration, sensor)};
    T_body_sensor = entry->T_body_sensor();
  }

  std::unique_ptr<io::SensorLogReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, io::SensorLogReader::open(options.log));
  const auto start = std::chrono::steady_clock::now();
  uint64_t outside_trajectory = 0;
  io::LogEntry entry;
  while (true) {
    bool more = false;
    HANZO_ASSIGN_OR_RETURN(more, reader->next(entry));
    if (!more) break;
    if (entry.topic != options.topic) continue;
    const auto* message = std::get_if<msgs::SensorMessage>(&entry.message);
    const auto* points = message != nullptr ? std::get_if<msgs::PointCloudMessage>(message) : nullptr;
    if (points == nullptr) return Error{fmt::format("{}: topic {} does not carry point clouds", options.log, options.topic)};
    const std::optional<SE3> T_world_body = pose_at(trajectory, points->timestamp);
    if (!T_world_body) {
      ++outside_trajectory;
      continue;
    }
    cloud::PointCloud scan;
    HANZO_ASSIGN_OR_RETURN(scan, cloud::from_message(*points));
    HANZO_RETURN_IF_ERROR(with_context(builder.insert(*T_world_body * T_body_sensor, scan),
                                       fmt::format("{} at {} s", options.topic, points->timestamp.seconds())));
  }
  HANZO_RETURN_IF_ERROR(reader->complete());  // a map of part of the log is not passed off as the whole
  if (builder.summary().scans == 0) {
    return Error{fmt::format("{}: no point cloud on topic {} within the trajectory's time span", options.log, options.topic)};
  }
  const double build_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  msgs::FusionMap map;
  map.map_id = options.map_id.empty() ? maps::generate_map_id() : options.map_id;
  map.version = 1;
  map.created = Timestamp::wall_clock_now();
  map.frame_id = options.frame;
  map.provenance.algorithm = "maps/known_poses";
  map.provenance.parameters = options_yaml(options);
  map.provenance.software_version = HANZO_FUSION_VERSION;
  for (const std::string& input : {options.log, options.trajectory}) {
    msgs::InputLog described;
    HANZO_ASSIGN_OR_RETURN(described, maps::describe_input_file(input));
    map.provenance.input_logs.push_back(described);
  }
  if (!options.calibration.empty()) {
    std::string calibration_text;
    HANZO_ASSIGN_OR_RETURN(calibration_text, read_file(options.calibration));
    map.sensor_configuration = calibration_text;
  }
  builder.write_map(map);
  HANZO_RETURN_IF_ERROR(maps::write_fusion_map(options.out, map));

  nlohmann::json result = describe_map(map);
  result["scans"] = builder.summary().scans;
  result["points_integrated"] = builder.summary().points;
  result["scans_outside_trajectory"] = outside_trajectory;
  result["build_seconds"] = build_seconds;
  result["ms_per_scan"] = 1e3 * build_seconds / static_cast<double>(builder.summary().scans);
  result["memory_bytes"] = builder.memory_bytes();
  result["out"] = options.out;
  return result;
}

}  // namespace

int run_map_build(const Output& output, const MapBuildOptions& options) {
  auto result = build(options);
  if (!result) return report_failure(output, {{"log", options.log}, {"out", options.out}}, result.error().message);
  nlohmann::json& json = *result;
  json["ok"] = true;
  const std::string text =
      fmt::format("map {} from {} scans of {} ({} outside the trajectory), {:.1f} ms per scan, {:.1f} MB while building\n{}wrote {}\n",
                  json["map_id"].get<std::string>(), json["scans"].get<uint64_t>(), options.topic,
                  json["scans_outside_trajectory"].get<uint64_t>(), json["ms_per_scan"].get<double>(),
                  static_cast<double>(json["memory_bytes"].get<std::size_t>()) / 1e6, describe_map_text(json), options.out);
  return report_success(output, json, text);
}

}  // namespace hanzo::fusion::app
