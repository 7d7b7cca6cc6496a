#include "hanzo/fusion/io/kitti_import.hpp"

#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <sstream>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "image_files.hpp"
#include "text_lines.hpp"

namespace hanzo::fusion::io {
namespace {

namespace fs = std::filesystem;
using Matrix34 = Eigen::Matrix<double, 3, 4, Eigen::RowMajor>;

// calib.txt: "NAME: 12 numbers" per line.
Result<std::map<std::string, Matrix34>> read_calib(const std::string& path) {
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_file(path));
  std::map<std::string, Matrix34> matrices;
  std::istringstream stream(text);
  std::string line;
  for (std::size_t line_number = 1; std::getline(stream, line); ++line_number) {
    const auto colon = line.find(':');
    if (colon == std::string::npos) continue;
    const std::vector<std::string> fields = split_fields(std::string_view(line).substr(colon + 1));
    if (fields.size() != 12) {
      return Error(fmt::format("{}:{}: {} has {} numbers (expected 12, a row-major 3x4 matrix)", path, line_number,
                               line.substr(0, colon), fields.size()));
    }
    Matrix34 matrix;
    for (int i = 0; i < 12; ++i) {
      const auto value = parse_double(fields[static_cast<std::size_t>(i)]);
      if (!value || !std::isfinite(*value)) {
        return Error(fmt::format("{}:{}: '{}' is not a finite number", path, line_number, fields[static_cast<std::size_t>(i)]));
      }
      matrix(i / 4, i % 4) = *value;
    }
    matrices[line.substr(0, colon)] = matrix;
  }
  return matrices;
}

// One increasing time a line (first field), each read by `parse`: times.txt's seconds since the
// start (at `origin`), or `export dataset`'s timestamps_ns.txt (Unix time, integer ns).
Result<std::vector<Timestamp>> read_frame_times(const std::string& path, const std::function<Result<Timestamp>(const std::string&)>& parse) {
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_file(path));
  std::vector<Timestamp> times;
  std::istringstream stream(text);
  std::string line;
  for (std::size_t line_number = 1; std::getline(stream, line); ++line_number) {
    const std::vector<std::string> fields = split_fields(line);
    if (fields.empty()) continue;
    const Result<Timestamp> time = parse(fields[0]);
    if (!time) return Error(fmt::format("{}:{}: {}", path, line_number, time.error().message));
    if (!times.empty() && *time <= times.back()) return Error(fmt::format("{}:{}: time {} does not increase", path, line_number, fields[0]));
    times.push_back(*time);
  }
  if (times.empty()) return Error(fmt::format("{}: no frame times", path));
  return times;
}

Result<std::vector<Timestamp>> read_times(const std::string& path, Timestamp origin) {
  return read_frame_times(path, [origin](const std::string& field) -> Result<Timestamp> {
    Result<Timestamp> seconds = parse_seconds(field);
    if (!seconds) return seconds.error();
    return origin + Duration::from_nanoseconds(seconds->nanoseconds());
  });
}

Result<std::vector<Timestamp>> read_nanosecond_times(const std::string& path) {
  return read_frame_times(path, [](const std::string& field) -> Result<Timestamp> {
    int64_t nanoseconds = 0;
    const auto [end, error] = std::from_chars(field.data(), field.data() + field.size(), nanoseconds);
    if (error != std::errc() || end != field.data() + field.size() || nanoseconds <= 0) return Error(fmt::format("'{}' is not a time in nanoseconds", field));
    return Timestamp::from_nanoseconds(nanoseconds);
  });
}

Result<msgs::PointCloudMessage> read_velodyne_bin(const std::string& path, Timestamp time) {
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, read_file(path));
  if (bytes.empty() || bytes.size() % 16 != 0) {
    return Error(fmt::format("{}: {} bytes is not a whole number of points (16 bytes: float32 x y z reflectance)", path, bytes.size()));
  }
  msgs::PointCloudMessage cloud;
  cloud.timestamp = time;
  cloud.frame_id = "lidar";
  const std::size_t count = bytes.size() / 16;
  cloud.points.reserve(count);
  cloud.intensities.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    float values[4];
    std::memcpy(values, bytes.data() + i * 16, sizeof values);
    if (!std::isfinite(values[0]) || !std::isfinite(values[1]) || !std::isfinite(values[2]) || !std::isfinite(values[3])) {
      return Error(fmt::format("{}: point {} is not finite", path, i));
    }
    cloud.points.emplace_back(values[0], values[1], values[2]);
    cloud.intensities.push_back(std::clamp(values[3], 0.0F, 1.0F));
  }
  return cloud;
}

// Rectified camera: intrinsics from P = K [I | t], and x_cam = x_cam0 + t with t = K^-1 P(:, 3).
msgs::CameraIntrinsics intrinsics_of(const Matrix34& P) { return {P(0, 0), P(1, 1), P(0, 2), P(1, 2), 0, 0}; }
SE3 T_cam0_cam(const Matrix34& P) {
  const Eigen::Matrix3d K = P.leftCols<3>();
  return SE3(SO3(), -(K.inverse() * P.col(3)));
}

SE3 to_se3(const Matrix34& matrix) {
  Eigen::Matrix4d full = Eigen::Matrix4d::Identity();
  full.topRows<3>() = matrix;
  return SE3::from_matrix(full);
}

std::size_t count_files(const fs::path& dir) {
  std::size_t count = 0;
  for (const auto& entry : fs::directory_iterator(dir)) count += entry.is_regular_file() ? 1 : 0;
  return count;
}

}  // namespace

Result<KittiImportReport> import_kitti(const std::string& sequence_dir, SensorLogWriter& writer, const KittiImportConfig& config) {
  const fs::path root(sequence_dir);
  if (!fs::is_directory(root)) return Error(fmt::format("{}: not a directory (expected a KITTI sequence folder)", sequence_dir));
  std::vector<Timestamp> times;
  HANZO_ASSIGN_OR_RETURN(times, read_times((root / "times.txt").string(), Timestamp::from_seconds(config.time_origin)));
  KittiImportReport report;
  // A sequence `export dataset` wrote also keeps the absolute times: those, when they match.
  if (const fs::path absolute = root / "timestamps_ns.txt"; fs::is_regular_file(absolute)) {
    std::vector<Timestamp> stamps;
    HANZO_ASSIGN_OR_RETURN(stamps, read_nanosecond_times(absolute.string()));
    if (stamps.size() != times.size()) {
      return Error(fmt::format("{}: {} times for the {} frames of times.txt", absolute.string(), stamps.size(), times.size()));
    }
    times = std::move(stamps);
    report.absolute_times = true;
  }
  std::map<std::string, Matrix34> calib;
  HANZO_ASSIGN_OR_RETURN(calib, read_calib((root / "calib.txt").string()));
  const auto tr = calib.count("Tr") ? calib.find("Tr") : calib.find("Tr_velo_to_cam");
  if (tr == calib.end()) return Error(fmt::format("{}: no Tr (velodyne -> cam0) line", (root / "calib.txt").string()));
  const SE3 T_cam0_lidar = to_se3(tr->second);
  const SE3 T_lidar_cam0 = T_cam0_lidar.inverse();

  report.frames = times.size();
  report.calibration.sensors.push_back(calib::SensorCalibration::from_transform(config.lidar_topic.substr(1), SE3()));

  // The streams present, each checked to hold one file per frame.
  struct Stream {
    fs::path dir;
    std::string topic;
    std::string extension;
  };
  std::vector<Stream> streams;
  auto add_stream = [&](const fs::path& dir, const std::string& topic, const std::string& extension) -> Status {
    if (!fs::is_directory(dir)) return ok_status();
    const std::size_t files = count_files(dir);
    if (files != times.size()) {
      return Error(fmt::format("{}: {} files for {} frames in times.txt", dir.string(), files, times.size()));
    }
    streams.push_back({dir, topic, extension});
    return ok_status();
  };
  HANZO_RETURN_IF_ERROR(add_stream(root / "velodyne", config.lidar_topic, ".bin"));
  std::map<std::string, msgs::CameraIntrinsics> intrinsics;
  if (config.import_images) {
    const std::pair<const char*, const std::string*> cameras[] = {{"0", &config.left_camera_topic}, {"1", &config.right_camera_topic}};
    for (const auto& [index, topic] : cameras) {
      const fs::path dir = root / fmt::format("image_{}", index);
      if (!fs::is_directory(dir)) continue;
      const auto P = calib.find(fmt::format("P{}", index));
      if (P == calib.end()) return Error(fmt::format("{}: no P{} line for {}", (root / "calib.txt").string(), index, dir.string()));
      HANZO_RETURN_IF_ERROR(add_stream(dir, *topic, ".png"));
      intrinsics[*topic] = intrinsics_of(P->second);
      calib::SensorCalibration camera =
          calib::SensorCalibration::from_transform(topic->substr(1), T_lidar_cam0 * T_cam0_cam(P->second));
      camera.camera = calib::CameraCalibration{intrinsics[*topic], {}};
      report.calibration.sensors.push_back(camera);
    }
  }
  if (streams.empty()) return Error(fmt::format("{}: no velodyne/ or image_0/ / image_1/ folder", sequence_dir));

  // Ground truth, converted from the camera-0 frame to the body (LiDAR) frame.
  fs::path poses = config.poses_path;
  if (poses.empty()) poses = root.parent_path().parent_path() / "poses" / (root.filename().string() + ".txt");
  if (!config.poses_path.empty() || fs::is_regular_file(poses)) {
    std::string text;
    HANZO_ASSIGN_OR_RETURN(text, read_file(poses.string()));
    Trajectory camera_poses;
    HANZO_ASSIGN_OR_RETURN(camera_poses, parse_trajectory(text, TrajectoryFormat::kKitti, poses.string(), &times));
    report.ground_truth.timestamps = camera_poses.timestamps;
    for (std::size_t i = 0; i < camera_poses.size(); ++i) {
      report.ground_truth.poses.push_back((T_lidar_cam0 * camera_poses.pose_se3(i) * T_cam0_lidar).matrix());
    }
    report.poses_path = poses.string();
  }

  for (std::size_t frame = 0; frame < times.size(); ++frame) {
    for (const Stream& stream : streams) {
      const std::string path = (stream.dir / fmt::format("{:06d}{}", frame, stream.extension)).string();
      const std::string sensor = stream.topic.substr(1);
      if (stream.extension == ".bin") {
        msgs::PointCloudMessage cloud;
        HANZO_ASSIGN_OR_RETURN(cloud, read_velodyne_bin(path, times[frame]));
        cloud.frame_id = sensor;
        report.points += cloud.points.size();
        HANZO_RETURN_IF_ERROR(with_context(writer.write(stream.topic, cloud), path));
        ++report.scans;
      } else {
        msgs::ImageMessage image;
        HANZO_ASSIGN_OR_RETURN(image, read_image_file(path, times[frame], sensor));
        if (image.encoding != msgs::ImageEncoding::kMono8 && image.encoding != msgs::ImageEncoding::kRgb8) {
          return Error(fmt::format("{}: expected an 8-bit gray or colour image", path));
        }
        msgs::CameraIntrinsics& camera = intrinsics.at(stream.topic);
        if (camera.width == 0) {  // the first image tells the size, for the log and the calibration
          camera.width = image.width;
          camera.height = image.height;
          for (calib::SensorCalibration& entry : report.calibration.sensors) {
            if (entry.sensor == sensor) entry.camera->intrinsics = camera;
          }
        }
        image.intrinsics = camera;
        HANZO_RETURN_IF_ERROR(with_context(writer.write(stream.topic, image), path));
        ++report.images;
      }
    }
  }
  return report;
}

}  // namespace hanzo::fusion::io
