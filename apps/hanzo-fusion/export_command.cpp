// hanzo-fusion export ros2bag --out DIR [--log LOG] [--trajectory FILE | --poses RUN/poses.csv]
// [--map MAP.fmap]: sensor data and results as a ROS 2 bag (io/ros2_bag_writer.hpp) for RViz 2
// and Foxglove; docs/sensor-logs.md.

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/io/ros2_bag_writer.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/maps/map_export.hpp"

namespace hanzo::fusion::app {
namespace {

struct ExportOptions {
  std::string out;
  std::string trajectory;
  std::string trajectory_format = "tum";
  std::string poses;
  std::string map;
  std::string log;
  std::string lidar_layout = "velodyne";
  std::string frame = std::string(msgs::kWorldFrame);
};

// Writes every sensor message of a log into the bag under its topic; wheel odometry becomes
// TwistStamped (speeds from consecutive distances; the first message of a topic 0). Returns
// the counts of what was left out (radar, estimates) by topic.
Result<std::map<std::string, uint64_t>> export_log(const std::string& path, io::ros2::LidarLayout layout,
                                                   const std::function<Status(const std::string&, const std::string&, Timestamp,
                                                                              const std::string&)>& write) {
  std::unique_ptr<io::SensorLogReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, io::SensorLogReader::open(path));
  std::map<std::string, uint64_t> left_out;
  std::map<std::string, msgs::WheelOdometryMessage> previous_wheels;
  io::LogEntry entry;
  while (true) {
    bool more = false;
    HANZO_ASSIGN_OR_RETURN(more, reader->next(entry));
    if (!more) return left_out;
    const auto* sensor = std::get_if<msgs::SensorMessage>(&entry.message);
    if (sensor == nullptr) {
      ++left_out[entry.topic];
      continue;
    }
    const std::string frame = entry.topic.substr(entry.topic.find_last_of('/') + 1);
    Status written = std::visit(
        [&](const auto& m) -> Status {
          using Message = std::decay_t<decltype(m)>;
          if constexpr (std::is_same_v<Message, msgs::ImuMessage>) {
            return write(entry.topic, "sensor_msgs/msg/Imu", entry.log_time, io::ros2::imu_cdr(m));
          } else if constexpr (std::is_same_v<Message, msgs::PointCloudMessage>) {
            return write(entry.topic, "sensor_msgs/msg/PointCloud2", entry.log_time, io::ros2::point_cloud_cdr(m, layout));
          } else if constexpr (std::is_same_v<Message, msgs::ImageMessage>) {
            return write(entry.topic, "sensor_msgs/msg/Image", entry.log_time, io::ros2::image_cdr(m));
          } else if constexpr (std::is_same_v<Message, msgs::GnssMessage>) {
            return write(entry.topic, "sensor_msgs/msg/NavSatFix", entry.log_time, io::ros2::navsatfix_cdr(m, frame));
          } else if constexpr (std::is_same_v<Message, msgs::WheelOdometryMessage>) {
            double speed = 0.0, yaw_rate = 0.0;
            const auto previous = previous_wheels.find(entry.topic);
            if (previous != previous_wheels.end()) {
              const double dt = (m.timestamp - previous->second.timestamp).seconds();
              const double left = m.left_distance - previous->second.left_distance;
              const double right = m.right_distance - previous->second.right_distance;
              if (dt > 0.0) {
                speed = 0.5 * (left + right) / dt;
                yaw_rate = (right - left) / m.wheel_separation / dt;
              }
            }
            previous_wheels[entry.topic] = m;
            return write(entry.topic, "geometry_msgs/msg/TwistStamped", entry.log_time,
                         io::ros2::twist_stamped_cdr(m.timestamp, m.frame_id, speed, yaw_rate));
          } else {
            ++left_out[entry.topic];
            return ok_status();
          }
        },
        *sensor);
    HANZO_RETURN_IF_ERROR(written);
  }
}

struct PoseWithCovariance {
  io::ros2::StampedPose pose;
  Eigen::Matrix<double, 6, 6> covariance;  // ROS order and frames
};

// The run's poses.csv: timestamp_ns, x..qz, then the upper triangle cov_ij of the covariance of
// (position error in the world, orientation error in the body frame), turned into ROS's
// (position, rotation about the world axes): the orientation rows rotated by R_world_body.
Result<std::vector<PoseWithCovariance>> read_run_poses(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Error(fmt::format("{}: cannot open", path));
  std::string line;
  std::getline(in, line);
  std::map<std::string, std::size_t> column;
  {
    std::istringstream names(line);
    std::size_t index = 0;
    for (std::string name; std::getline(names, name, ',');) column[name] = index++;
  }
  for (const char* name : {"timestamp_ns", "x", "y", "z", "qw", "qx", "qy", "qz", "cov_55"}) {
    if (column.count(name) == 0) return Error(fmt::format("{}: no column '{}' (expected the poses.csv of `hanzo-fusion run`)", path, name));
  }
  std::vector<PoseWithCovariance> poses;
  for (int line_number = 2; std::getline(in, line); ++line_number) {
    if (line.empty()) continue;
    std::vector<std::string> fields;
    std::istringstream cells(line);
    for (std::string cell; std::getline(cells, cell, ',');) fields.push_back(cell);
    auto number = [&](const std::string& name) -> Result<double> {
      const std::size_t at = column.at(name);
      try {
        std::size_t used = 0;
        const double value = at < fields.size() ? std::stod(fields[at], &used) : std::nan("");
        if (at < fields.size() && used == fields[at].size() && std::isfinite(value)) return value;
      } catch (const std::exception&) {
      }
      return Error(fmt::format("{}:{}: column {} is not a finite number", path, line_number, name));
    };
    PoseWithCovariance pose;
    double value = 0.0;
    HANZO_ASSIGN_OR_RETURN(value, number("timestamp_ns"));
    pose.pose.stamp = Timestamp::from_nanoseconds(static_cast<int64_t>(value));
    double p[7];
    const char* names[] = {"x", "y", "z", "qw", "qx", "qy", "qz"};
    for (int i = 0; i < 7; ++i) HANZO_ASSIGN_OR_RETURN(p[i], number(names[i]));
    pose.pose.pose.position = {p[0], p[1], p[2]};
    pose.pose.pose.orientation = Eigen::Quaterniond(p[3], p[4], p[5], p[6]).normalized();
    Eigen::Matrix<double, 6, 6> body;
    for (int i = 0; i < 6; ++i) {
      for (int j = i; j < 6; ++j) {
        HANZO_ASSIGN_OR_RETURN(body(i, j), number(fmt::format("cov_{}{}", i, j)));
        body(j, i) = body(i, j);
      }
    }
    Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Identity();
    J.bottomRightCorner<3, 3>() = pose.pose.pose.orientation.toRotationMatrix();
    pose.covariance = J * body * J.transpose();
    poses.push_back(pose);
  }
  if (poses.empty()) return Error(fmt::format("{}: no poses", path));
  return poses;
}

int run_export_ros2bag(const Output& output, const ExportOptions& options) {
  nlohmann::json result = {{"format", "ros2bag"}, {"out", options.out}};
  if (options.trajectory.empty() && options.poses.empty() && options.map.empty() && options.log.empty()) {
    return report_failure(output, result, "nothing to export: give --log, --trajectory, --poses and/or --map");
  }
  Result<io::ros2::LidarLayout> layout = io::ros2::lidar_layout_from_name(options.lidar_layout);
  if (!layout) return report_failure(output, result, "--lidar-layout: " + layout.error().message);
  if (!options.trajectory.empty() && !options.poses.empty()) {
    return report_failure(output, result, "--trajectory and --poses both give the trajectory: give one");
  }
  // Read everything first: a bad input leaves no bag behind.
  std::vector<io::ros2::StampedPose> path;
  std::vector<PoseWithCovariance> poses_with_covariance;
  if (!options.trajectory.empty()) {
    Result<io::TrajectoryFormat> format = io::trajectory_format_from_name(options.trajectory_format);
    if (!format) return report_failure(output, result, format.error().message);
    Result<io::Trajectory> trajectory = io::read_trajectory(options.trajectory, *format);
    if (!trajectory) return report_failure(output, result, trajectory.error().message);
    for (std::size_t i = 0; i < trajectory->poses.size(); ++i) {
      path.push_back({trajectory->timestamps[i], msgs::Pose::from_se3(SE3::from_matrix(trajectory->poses[i]))});
    }
  } else if (!options.poses.empty()) {
    auto read = read_run_poses(options.poses);
    if (!read) return report_failure(output, result, read.error().message);
    poses_with_covariance = std::move(*read);
    for (const PoseWithCovariance& pose : poses_with_covariance) path.push_back(pose.pose);
  }
  std::optional<msgs::FusionMap> map;
  if (!options.map.empty()) {
    Result<msgs::FusionMap> read = maps::read_fusion_map(options.map);
    if (!read) return report_failure(output, result, read.error().message);
    map = std::move(*read);
  }
  auto writer = io::ros2::BagWriter::create(options.out);
  if (!writer) return report_failure(output, result, writer.error().message);
  std::map<std::string, uint64_t> counts;
  auto write = [&](const std::string& topic, const std::string& type, Timestamp time, const std::string& cdr) -> Status {
    ++counts[topic];
    return (*writer)->write(topic, type, time, cdr);
  };
  std::map<std::string, uint64_t> left_out;
  const Status written = [&]() -> Status {
    if (!options.log.empty()) HANZO_ASSIGN_OR_RETURN(left_out, export_log(options.log, *layout, write));
    for (std::size_t i = 0; i < path.size(); ++i) {
      if (poses_with_covariance.empty()) {
        HANZO_RETURN_IF_ERROR(write("/pose", "geometry_msgs/msg/PoseStamped", path[i].stamp,
                                    io::ros2::pose_stamped_cdr(path[i].stamp, options.frame, path[i].pose)));
      } else {
        HANZO_RETURN_IF_ERROR(write("/pose", "geometry_msgs/msg/PoseWithCovarianceStamped", path[i].stamp,
                                    io::ros2::pose_with_covariance_stamped_cdr(path[i].stamp, options.frame, path[i].pose,
                                                                               poses_with_covariance[i].covariance)));
      }
    }
    if (!path.empty()) {
      HANZO_RETURN_IF_ERROR(write("/trajectory", "nav_msgs/msg/Path", path.back().stamp,
                                  io::ros2::path_cdr(path.back().stamp, options.frame, path)));
    }
    if (map) {
      const Timestamp time = !path.empty() ? path.back().stamp : map->created;
      if (map->points) {
        HANZO_RETURN_IF_ERROR(write("/map/points", "sensor_msgs/msg/PointCloud2", time,
                                    io::ros2::point_cloud_cdr(time, map->frame_id, map->points->points, map->points->intensities)));
      }
      if (map->occupancy) {
        std::string grid;
        HANZO_ASSIGN_OR_RETURN(grid, io::ros2::occupancy_grid_cdr(time, map->frame_id, maps::flatten_occupancy(*map->occupancy)));
        HANZO_RETURN_IF_ERROR(write("/map/occupancy", "nav_msgs/msg/OccupancyGrid", time, grid));
      }
      if (!map->points && !map->occupancy) return Error(fmt::format("{}: the map has no point or occupancy layer to export", options.map));
    }
    return (*writer)->close();
  }();
  if (!written) {
    writer->reset();
    std::error_code ignored;
    std::filesystem::remove_all(options.out, ignored);
    return report_failure(output, result, written.error().message);
  }
  result["ok"] = true;
  result["topics"] = counts;
  result["left_out"] = left_out;
  std::string text = fmt::format("{}: ROS 2 bag (MCAP)\n", options.out);
  for (const auto& [topic, count] : counts) text += fmt::format("  {}: {} messages\n", topic, count);
  for (const auto& [topic, count] : left_out) text += fmt::format("  {}: {} messages left out (no ROS 2 type written for them)\n", topic, count);
  return report_success(output, result, text);
}

}  // namespace

void add_export_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* export_app = app.add_subcommand("export", "Export results in other ecosystems' formats");
  export_app->require_subcommand(1);
  auto options = std::make_shared<ExportOptions>();
  CLI::App* ros2bag = export_app->add_subcommand("ros2bag", "A trajectory and a map as a ROS 2 bag (MCAP) for RViz 2 and Foxglove");
  ros2bag->add_option("--out", options->out, "Bag folder to create (must not exist)")->required();
  ros2bag->add_option("--trajectory", options->trajectory, "Trajectory file -> /trajectory (nav_msgs/Path) and /pose (PoseStamped)");
  ros2bag->add_option("--trajectory-format", options->trajectory_format, "tum, kitti or euroc")->capture_default_str();
  ros2bag->add_option("--poses", options->poses,
                      "A run's poses.csv -> /trajectory and /pose as PoseWithCovarianceStamped (instead of --trajectory)");
  ros2bag->add_option("--map", options->map, "FusionMap -> /map/points (PointCloud2), /map/occupancy (OccupancyGrid)");
  ros2bag->add_option("--log", options->log,
                      "Sensor log: IMU, clouds, images, GNSS, wheel odometry (as TwistStamped) under their topics");
  ros2bag->add_option("--lidar-layout", options->lidar_layout, "Point layout of the clouds: plain, velodyne, ouster, livox, hesai")
      ->capture_default_str();
  ros2bag->add_option("--frame", options->frame, "frame_id of the trajectory's poses")->capture_default_str();
  ros2bag->callback([&output, &run, options] { run = [&output, options] { return run_export_ros2bag(output, *options); }; });
}

}  // namespace hanzo::fusion::app
