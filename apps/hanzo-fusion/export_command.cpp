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
#include "hanzo/fusion/calib/calibration.hpp"
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
  std::string calibration;
  std::string body_frame = "base_link";
  std::string storage = "mcap";
  bool raw_images = false;
};


using WriteFunction = std::function<Status(const std::string&, const std::string&, Timestamp, const std::string&)>;

// The message with `frame_id` set where it was empty (GNSS fixes carry none).
msgs::SensorMessage with_frame(const msgs::SensorMessage& message, const std::string& frame_id) {
  msgs::SensorMessage named = message;
  std::visit(
      [&](auto& m) {
        if constexpr (!std::is_same_v<std::decay_t<decltype(m)>, msgs::GnssMessage>) {
          if (m.frame_id.empty()) m.frame_id = frame_id;
        }
      },
      named);
  return named;
}

std::string frame_of(const msgs::SensorMessage& message) {
  return std::visit(
      [](const auto& m) -> std::string {
        if constexpr (std::is_same_v<std::decay_t<decltype(m)>, msgs::GnssMessage>) {
          return "";
        } else {
          return m.frame_id;
        }
      },
      message);
}

struct ExportedLog {
  std::map<std::string, uint64_t> left_out;   // topic -> messages without a ROS 2 type written for them
  std::vector<std::string> calibrated;        // sensors placed in /tf_static
  std::map<std::string, std::string> sensor_by_topic;  // the exported topics' sensor names
  std::optional<double> wheel_separation;     // m, of the first wheel message
  std::map<std::string, std::string> label_images;  // ROS topic of a segmentation's label images -> its detections' log topic
};

// What the import needs to give back the same log (rosbag_import.hpp): the topics' sensor names,
// the wheel separation and the calibration, as metadata.yaml's custom_data.
std::map<std::string, std::string> recorded_log(const ExportedLog& exported, const calib::Calibration* calibration) {
  std::map<std::string, std::string> custom_data;
  if (!exported.sensor_by_topic.empty()) custom_data["hanzo_fusion.sensors"] = nlohmann::json(exported.sensor_by_topic).dump();
  if (exported.wheel_separation) custom_data["hanzo_fusion.wheel_separation"] = fmt::format("{}", *exported.wheel_separation);
  if (calibration != nullptr) custom_data["hanzo_fusion.calibration"] = calib::to_yaml(*calibration);
  if (!exported.label_images.empty()) custom_data["hanzo_fusion.label_images"] = nlohmann::json(exported.label_images).dump();
  return custom_data;
}

// Writes every sensor message of a log into the bag under its topic; wheel odometry becomes
// TwistStamped (speeds from consecutive distances; the first message of a topic 0). An 8-bit
// image stored as a JPEG / PNG file goes out as CompressedImage with that file (Image with
// `raw_images`; depth always as Image). With a
// calibration, each sensor it places (by the channel's sensor name) gets a static transform
// from `body_frame` to its messages' frame (named after the sensor when they carry none) in
// /tf_static, and each calibrated camera a CameraInfo with every image on <topic>/camera_info.
Result<ExportedLog> export_log(const std::string& path, io::ros2::LidarLayout layout, const calib::Calibration* calibration,
                               const std::string& body_frame, bool raw_images, const WriteFunction& write) {
  std::unique_ptr<io::SensorLogReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, io::SensorLogReader::open(path));
  std::map<std::string, std::string> sensor_by_topic;
  for (const auto& [id, channel] : reader->mcap().channels()) {
    if (const auto sensor = channel.metadata.find("sensor"); sensor != channel.metadata.end()) sensor_by_topic[channel.topic] = sensor->second;
  }
  ExportedLog exported;
  std::map<std::string, msgs::WheelOdometryMessage> previous_wheels;
  std::map<std::string, std::vector<std::string>> label_tables;  // label_info topic -> the classes last written
  std::vector<io::ros::FrameTransform> transforms;
  std::optional<Timestamp> first_time;
  io::LogEntry entry;
  while (true) {
    bool more = false;
    HANZO_ASSIGN_OR_RETURN(more, reader->next(entry));
    if (!more) break;
    const auto* logged = std::get_if<msgs::SensorMessage>(&entry.message);
    if (logged == nullptr) {
      ++exported.left_out[entry.topic];
      continue;
    }
    if (!first_time) first_time = entry.log_time;
    const std::string sensor_name = sensor_by_topic.count(entry.topic) ? sensor_by_topic.at(entry.topic) : "";
    const calib::SensorCalibration* placed = calibration && !sensor_name.empty() ? calibration->find(sensor_name) : nullptr;
    const bool needs_frame = placed != nullptr && frame_of(*logged).empty() && !std::holds_alternative<msgs::GnssMessage>(*logged);
    const msgs::SensorMessage named = needs_frame ? with_frame(*logged, sensor_name) : msgs::SensorMessage{};
    const msgs::SensorMessage& message = needs_frame ? named : *logged;
    if (placed != nullptr && std::find(exported.calibrated.begin(), exported.calibrated.end(), sensor_name) == exported.calibrated.end()) {
      const std::string child = std::holds_alternative<msgs::GnssMessage>(message) ? entry.topic.substr(entry.topic.find_last_of('/') + 1)
                                                                                    : frame_of(message);
      transforms.push_back({*first_time, body_frame, child, placed->T_body_sensor()});
      exported.calibrated.push_back(sensor_name);
    }
    const std::string frame = entry.topic.substr(entry.topic.find_last_of('/') + 1);
    if (!sensor_name.empty()) exported.sensor_by_topic[entry.topic] = sensor_name;
    if (const auto* wheels = std::get_if<msgs::WheelOdometryMessage>(&message); wheels && !exported.wheel_separation) {
      exported.wheel_separation = wheels->wheel_separation;
    }
    Status written = std::visit(
        [&](const auto& m) -> Status {
          using Message = std::decay_t<decltype(m)>;
          if constexpr (std::is_same_v<Message, msgs::ImuMessage>) {
            return write(entry.topic, "sensor_msgs/msg/Imu", entry.log_time, io::ros2::imu_cdr(m));
          } else if constexpr (std::is_same_v<Message, msgs::PointCloudMessage>) {
            return write(entry.topic, "sensor_msgs/msg/PointCloud2", entry.log_time, io::ros2::point_cloud_cdr(m, layout));
          } else if constexpr (std::is_same_v<Message, msgs::ImageMessage>) {
            if (raw_images || entry.stored_image_format.empty()) {
              HANZO_RETURN_IF_ERROR(write(entry.topic, "sensor_msgs/msg/Image", entry.log_time, io::ros2::image_cdr(m)));
            } else {
              HANZO_RETURN_IF_ERROR(write(entry.topic, "sensor_msgs/msg/CompressedImage", entry.log_time,
                                          io::ros2::compressed_image_cdr(m, entry.stored_image_format, entry.stored_image_file)));
            }
            if (placed == nullptr || !placed->camera) return ok_status();
            return write(entry.topic + "/camera_info", "sensor_msgs/msg/CameraInfo", entry.log_time,
                         io::ros2::camera_info_cdr(m.timestamp, m.frame_id, *placed->camera, m.width, m.height));
          } else if constexpr (std::is_same_v<Message, msgs::GnssMessage>) {
            return write(entry.topic, "sensor_msgs/msg/NavSatFix", entry.log_time, io::ros2::navsatfix_cdr(m, frame));
          } else if constexpr (std::is_same_v<Message, msgs::DetectionsMessage>) {
            // <camera>/detections; a segmentation as <camera>/segmentation with its classes on <camera>/label_info.
            HANZO_RETURN_IF_ERROR(write(entry.topic, "vision_msgs/msg/Detection2DArray", entry.log_time, io::ros2::detection_array_cdr(m)));
            if (m.segmentation.empty()) return ok_status();
            const std::string camera = entry.topic.substr(0, entry.topic.find_last_of('/'));
            std::vector<std::string>& classes = label_tables[camera + "/label_info"];
            if (classes != m.segmentation_classes) {
              classes = m.segmentation_classes;
              HANZO_RETURN_IF_ERROR(write(camera + "/label_info", "vision_msgs/msg/LabelInfo", entry.log_time,
                                          io::ros2::label_info_cdr(m.timestamp, m.frame_id, classes)));
            }
            exported.label_images[camera + "/segmentation"] = entry.topic;
            return write(camera + "/segmentation", "sensor_msgs/msg/Image", entry.log_time, io::ros2::label_image_cdr(m));
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
            ++exported.left_out[entry.topic];
            return ok_status();
          }
        },
        message);
    HANZO_RETURN_IF_ERROR(written);
  }
  HANZO_RETURN_IF_ERROR(reader->complete());  // a partial log is not exported as a whole one
  if (!transforms.empty()) HANZO_RETURN_IF_ERROR(write("/tf_static", "tf2_msgs/msg/TFMessage", *first_time, io::ros2::tf_message_cdr(transforms)));
  return exported;
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
  Result<io::ros2::BagStorage> storage = io::ros2::bag_storage_from_name(options.storage);
  if (!storage) return report_failure(output, result, "--storage: " + storage.error().message);
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
  std::optional<calib::Calibration> calibration;
  if (!options.calibration.empty()) {
    if (options.log.empty()) return report_failure(output, result, "--calib places the sensors of --log: give --log too");
    Result<calib::Calibration> loaded = calib::load_calibration(options.calibration);
    if (!loaded) return report_failure(output, result, loaded.error().message);
    calibration = std::move(*loaded);
  }
  std::optional<msgs::FusionMap> map;
  if (!options.map.empty()) {
    Result<msgs::FusionMap> read = maps::read_fusion_map(options.map);
    if (!read) return report_failure(output, result, read.error().message);
    map = std::move(*read);
  }
  auto writer = io::ros2::BagWriter::create(options.out, *storage);
  if (!writer) return report_failure(output, result, writer.error().message);
  std::map<std::string, uint64_t> counts;
  auto write = [&](const std::string& topic, const std::string& type, Timestamp time, const std::string& cdr) -> Status {
    ++counts[topic];
    return (*writer)->write(topic, type, time, cdr);
  };
  ExportedLog exported_log;
  const Status written = [&]() -> Status {
    if (!options.log.empty()) {
      HANZO_ASSIGN_OR_RETURN(exported_log, export_log(options.log, *layout, calibration ? &*calibration : nullptr, options.body_frame,
                                                            options.raw_images, write));
    }
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
    (*writer)->set_custom_data(recorded_log(exported_log, calibration ? &*calibration : nullptr));
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
  result["left_out"] = exported_log.left_out;
  if (calibration) result["calibrated_sensors"] = exported_log.calibrated;
  result["storage"] = options.storage;
  std::string text = fmt::format("{}: ROS 2 bag ({})\n", options.out, options.storage);
  for (const auto& [topic, count] : counts) text += fmt::format("  {}: {} messages\n", topic, count);
  if (calibration) {
    std::string names;
    for (const std::string& name : exported_log.calibrated) names += (names.empty() ? "" : ", ") + name;
    text += fmt::format("  /tf_static: {} placed from {} ({})\n", options.body_frame, options.calibration, names.empty() ? "no sensor" : names);
  }
  for (const auto& [topic, count] : exported_log.left_out) text += fmt::format("  {}: {} messages left out (no ROS 2 type written for them)\n", topic, count);
  return report_success(output, result, text);
}

}  // namespace

void add_export_command(CLI::App& app, const Output& output, Command& run) {
  CLI::App* export_app = app.add_subcommand("export", "Export results in other ecosystems' formats");
  export_app->require_subcommand(1);
  auto options = std::make_shared<ExportOptions>();
  CLI::App* ros2bag = export_app->add_subcommand("ros2bag", "A trajectory, a map and sensor data as a ROS 2 bag for RViz 2 and Foxglove");
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
  ros2bag->add_option("--calib", options->calibration,
                      "With --log: the sensors' extrinsics as /tf_static, camera intrinsics as <image topic>/camera_info");
  ros2bag->add_option("--body-frame", options->body_frame, "Parent frame of /tf_static")->capture_default_str();
  ros2bag->add_option("--storage", options->storage, "mcap (ROS 2 Iron and later) or sqlite3 (.db3: Foxy to Humble)")->capture_default_str();
  ros2bag->add_flag("--raw-images", options->raw_images,
                    "Write every image as sensor_msgs/Image (by default a log's JPEG / PNG images go out unchanged as CompressedImage)");
  ros2bag->callback([&output, &run, options] { run = [&output, options] { return run_export_ros2bag(output, *options); }; });

  add_export_dataset_command(*export_app, output, run);
}

}  // namespace hanzo::fusion::app
