#include "hanzo/fusion/io/dataset_export.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <utility>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "dataset_layouts.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "image_compression.hpp"

namespace hanzo::fusion::io {

Result<DatasetLayout> dataset_layout_from_name(const std::string& name) {
  if (name == "kitti") return DatasetLayout::kKittiOdometry;
  if (name == "nuscenes") return DatasetLayout::kNuscenes;
  return Error(fmt::format("unknown dataset layout '{}' (expected kitti or nuscenes)", name));
}

namespace dataset {

Status DatasetLayoutWriter::write_file(const std::string& path, const std::string& bytes) {
  std::ofstream file(path, std::ios::binary | std::ios::trunc);
  file.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  file.close();
  if (!file) return Error(fmt::format("{}: cannot write the file", path));
  bytes_written_ += bytes.size();
  return ok_status();
}

Result<std::string> encode_image(const msgs::ImageMessage& image, bool jpeg, int jpeg_quality) {
  msgs::ImageMessage input = image;
  if (image.encoding == msgs::ImageEncoding::kDepth32f) {
    // Metres as float -> millimetres as uint16 (0: no measurement), the usual depth PNG.
    input.encoding = msgs::ImageEncoding::kDepth16;
    input.data.assign(static_cast<std::size_t>(image.width) * image.height * 2, 0);
    const auto* metres = reinterpret_cast<const float*>(image.data.data());
    auto* millimetres = reinterpret_cast<uint16_t*>(input.data.data());
    for (std::size_t i = 0; i < static_cast<std::size_t>(image.width) * image.height; ++i) {
      const float value = metres[i] * 1000.0F;
      millimetres[i] = std::isfinite(value) && value > 0.0F ? static_cast<uint16_t>(std::min(value + 0.5F, 65535.0F)) : 0;
    }
  }
  const bool use_jpeg = jpeg && input.encoding != msgs::ImageEncoding::kDepth16;
  const v1::ImageMessage encoded = compressed_image(input, use_jpeg ? ImageCompression::kJpeg : ImageCompression::kPng, jpeg_quality);
  if (encoded.compression().empty()) return Error(fmt::format("an image of encoding {} cannot be written as a file", msgs::to_string(image.encoding)));
  return encoded.data();
}

}  // namespace dataset

namespace {

using dataset::LayoutCloud;
using dataset::LayoutFrame;
using dataset::LayoutSensor;

// T_world_body at any time the trajectory covers, interpolated on SE3.
class TrajectoryInterpolator {
 public:
  TrajectoryInterpolator(const Trajectory& trajectory, double max_gap_s) : trajectory_(trajectory), max_gap_(Duration::from_seconds(max_gap_s)) {
    poses_.reserve(trajectory.size());
    for (std::size_t i = 0; i < trajectory.size(); ++i) poses_.push_back(trajectory.pose_se3(i));
  }

  std::optional<SE3> at(Timestamp time) const {
    const std::vector<Timestamp>& times = trajectory_.timestamps;
    if (times.empty() || time < times.front() || time > times.back()) return std::nullopt;
    const auto after = std::lower_bound(times.begin(), times.end(), time);
    const std::size_t j = static_cast<std::size_t>(after - times.begin());
    if (times[j] == time) return poses_[j];
    const std::size_t i = j - 1;
    if (times[j] - times[i] > max_gap_) return std::nullopt;
    return SE3::interpolate(poses_[i], poses_[j], (time - times[i]).seconds() / (times[j] - times[i]).seconds());
  }

  // As at(), with times outside the trajectory clamped to its ends (deskewing the edges of a sweep).
  SE3 clamped(Timestamp time) const {
    const Timestamp clamped_time = std::clamp(time, trajectory_.timestamps.front(), trajectory_.timestamps.back());
    if (std::optional<SE3> pose = at(clamped_time)) return *pose;
    const auto after = std::lower_bound(trajectory_.timestamps.begin(), trajectory_.timestamps.end(), clamped_time);
    return poses_[static_cast<std::size_t>(std::min<std::ptrdiff_t>(after - trajectory_.timestamps.begin(), static_cast<std::ptrdiff_t>(poses_.size()) - 1))];
  }

 private:
  const Trajectory& trajectory_;
  Duration max_gap_;
  std::vector<SE3> poses_;
};

// Points moved into the sensor frame at the message time: p' = T_ws(t0)^-1 T_ws(t_i) p, with the
// relative motion sampled at 33 times over the sweep and interpolated between them per point.
LayoutCloud deskewed(const msgs::PointCloudMessage& cloud, const TrajectoryInterpolator& poses, const SE3& T_body_sensor, Duration offset) {
  LayoutCloud out{cloud.points, cloud.intensities, cloud.ring_ids};
  const auto [earliest, latest] = std::minmax_element(cloud.point_timestamps.begin(), cloud.point_timestamps.end());
  const double span = (*latest - *earliest).seconds();
  if (span <= 0.0) return out;
  constexpr int kSamples = 33;
  const SE3 T_sensor_world = (poses.clamped(cloud.timestamp + offset) * T_body_sensor).inverse();
  std::vector<Eigen::Quaterniond> rotations(kSamples);
  std::vector<Eigen::Vector3d> translations(kSamples);
  for (int k = 0; k < kSamples; ++k) {
    const Timestamp time = *earliest + Duration::from_seconds(span * k / (kSamples - 1)) + offset;
    const SE3 relative = T_sensor_world * poses.clamped(time) * T_body_sensor;
    rotations[static_cast<std::size_t>(k)] = relative.rotation().quaternion();
    translations[static_cast<std::size_t>(k)] = relative.translation();
  }
  for (std::size_t i = 0; i < out.points.size(); ++i) {
    const double position = (cloud.point_timestamps[i] - *earliest).seconds() / span * (kSamples - 1);
    const int k = std::clamp(static_cast<int>(position), 0, kSamples - 2);
    const double fraction = position - k;
    const auto a = static_cast<std::size_t>(k);
    const Eigen::Quaterniond rotation = rotations[a].slerp(fraction, rotations[a + 1]);
    const Eigen::Vector3d translation = (1.0 - fraction) * translations[a] + fraction * translations[a + 1];
    out.points[i] = (rotation * out.points[i].cast<double>() + translation).cast<float>();
  }
  return out;
}

// The remap tables that undistort one camera's images onto its pinhole intrinsics.
struct UndistortMaps {
  cv::Mat map_x, map_y;
};

UndistortMaps undistort_maps(const PinholeCamera& camera, int width, int height) {
  UndistortMaps maps{cv::Mat(height, width, CV_32FC1), cv::Mat(height, width, CV_32FC1)};
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector2d distorted = camera.distort({(u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy});
      maps.map_x.at<float>(v, u) = static_cast<float>(camera.fx * distorted.x() + camera.cx);
      maps.map_y.at<float>(v, u) = static_cast<float>(camera.fy * distorted.y() + camera.cy);
    }
  }
  return maps;
}

int cv_type(msgs::ImageEncoding encoding) {
  switch (encoding) {
    case msgs::ImageEncoding::kMono8: return CV_8UC1;
    case msgs::ImageEncoding::kRgb8:
    case msgs::ImageEncoding::kBgr8: return CV_8UC3;
    case msgs::ImageEncoding::kDepth16: return CV_16UC1;
    case msgs::ImageEncoding::kDepth32f: return CV_32FC1;
  }
  return CV_8UC1;
}

msgs::ImageMessage undistorted(const msgs::ImageMessage& image, const UndistortMaps& maps) {
  const cv::Mat input(static_cast<int>(image.height), static_cast<int>(image.width), cv_type(image.encoding), const_cast<uint8_t*>(image.data.data()));
  cv::Mat output;
  const bool depth = image.encoding == msgs::ImageEncoding::kDepth16 || image.encoding == msgs::ImageEncoding::kDepth32f;
  // Depth is not blended across edges: nearest neighbour.
  cv::remap(input, output, maps.map_x, maps.map_y, depth ? cv::INTER_NEAREST : cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  msgs::ImageMessage out = image;
  out.data.assign(output.data, output.data + output.total() * output.elemSize());
  out.distortion = msgs::DistortionModel{};
  return out;
}

// A frame: the reference message's time and, per sensor, the time of the message it takes.
struct PlannedFrame {
  Timestamp time;
  SE3 T_world_body;
  std::vector<std::optional<Timestamp>> message_times;  // per sensor; the reference's own included
};

std::optional<Timestamp> nearest(const std::vector<Timestamp>& times, Timestamp time, Duration max_difference) {
  const auto after = std::lower_bound(times.begin(), times.end(), time);
  std::optional<Timestamp> best;
  if (after != times.end()) best = *after;
  if (after != times.begin() && (!best || time - *(after - 1) <= *best - time)) best = *(after - 1);
  if (!best || (*best > time ? *best - time : time - *best) > max_difference) return std::nullopt;
  return best;
}

// Calls `visit(sensor index, topic, message)` for every sensor message of the log on a topic of
// `sensor_by_topic`, in log order; stops at the first error.
Status visit_sensor_messages(const std::string& log_path, const std::map<std::string, std::size_t>& sensor_by_topic,
                             const std::function<Status(std::size_t, const std::string&, const msgs::SensorMessage&)>& visit) {
  std::unique_ptr<SensorLogReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, SensorLogReader::open(log_path));
  LogEntry entry;
  while (true) {
    bool more = false;
    HANZO_ASSIGN_OR_RETURN(more, reader->next(entry));
    if (!more) return reader->complete();  // a dataset of part of the log is not passed off as the whole
    const auto found = sensor_by_topic.find(entry.topic);
    const auto* message = std::get_if<msgs::SensorMessage>(&entry.message);
    if (found != sensor_by_topic.end() && message != nullptr) HANZO_RETURN_IF_ERROR(visit(found->second, entry.topic, *message));
  }
}

Status check_config(const DatasetExportConfig& config) {
  if (config.sensors.empty()) return Error("no sensors to export: name at least one LiDAR or camera");
  if (config.every < 1) return Error(fmt::format("every: expected an integer >= 1, got {}", config.every));
  if (!(config.max_time_difference_s > 0.0)) return Error("max_time_difference_s: expected a positive number of seconds");
  if (!(config.max_trajectory_gap_s > 0.0)) return Error("max_trajectory_gap_s: expected a positive number of seconds");
  if (config.jpeg_quality < 1 || config.jpeg_quality > 100) return Error(fmt::format("jpeg_quality: expected 1..100, got {}", config.jpeg_quality));
  std::set<std::string> names, topics;
  for (const DatasetSensor& sensor : config.sensors) {
    if (!names.insert(sensor.name).second) return Error(fmt::format("sensor '{}' is named twice", sensor.name));
    if (!topics.insert(sensor.topic).second) return Error(fmt::format("topic '{}' is given for two sensors", sensor.topic));
  }
  return ok_status();
}

}  // namespace

Result<DatasetExportSummary> export_dataset(const std::string& log_path, const Trajectory& trajectory, const calib::Calibration& calibration,
                                            const std::string& out_dir, const DatasetExportConfig& config) {
  HANZO_RETURN_IF_ERROR(check_config(config));
  if (trajectory.empty()) return Error("the trajectory is empty");
  // The sensors: calibration, reference.
  std::vector<LayoutSensor> sensors;
  std::vector<Duration> time_offsets;
  std::vector<std::optional<PinholeCamera>> cameras;
  std::map<std::string, std::size_t> sensor_by_topic;
  std::optional<std::size_t> reference;
  for (const DatasetSensor& sensor : config.sensors) {
    const calib::SensorCalibration* entry = calibration.find(sensor.name);
    if (entry == nullptr) return Error(fmt::format("sensor '{}' has no entry '{}_to_body' in the calibration", sensor.name, sensor.name));
    LayoutSensor layout{sensor.name, sensor.is_camera, entry->T_body_sensor(), {}};
    std::optional<PinholeCamera> camera;
    if (sensor.is_camera) {
      if (!entry->camera) return Error(fmt::format("camera '{}' has no intrinsics in the calibration", sensor.name));
      layout.intrinsics = entry->camera->intrinsics;
      camera = entry->camera->pinhole_camera();
    }
    sensor_by_topic[sensor.topic] = sensors.size();
    if (sensor.name == config.reference_sensor) reference = sensors.size();
    sensors.push_back(layout);
    time_offsets.push_back(entry->time_offset);
    cameras.push_back(camera);
  }
  if (!config.reference_sensor.empty() && !reference) {
    return Error(fmt::format("reference sensor '{}' is not among the exported sensors", config.reference_sensor));
  }
  if (!reference) {
    const auto lidar = std::find_if(sensors.begin(), sensors.end(), [](const LayoutSensor& s) { return !s.is_camera; });
    reference = static_cast<std::size_t>((lidar != sensors.end() ? lidar : sensors.begin()) - sensors.begin());
  }

  // Pass 1: the message times of every sensor (body clock).
  std::vector<std::vector<Timestamp>> times(sensors.size());
  HANZO_RETURN_IF_ERROR(visit_sensor_messages(log_path, sensor_by_topic, [&](std::size_t s, const std::string& topic, const msgs::SensorMessage& message) -> Status {
    const bool is_image = std::holds_alternative<msgs::ImageMessage>(message);
    const bool is_cloud = std::holds_alternative<msgs::PointCloudMessage>(message);
    if (sensors[s].is_camera ? !is_image : !is_cloud) {
      return Error(fmt::format("{}: topic {} carries {} messages, not {} ({})", log_path, topic, msgs::modality_name(message),
                               sensors[s].is_camera ? "images" : "point clouds", sensors[s].name));
    }
    times[s].push_back(msgs::timestamp_of(message) + time_offsets[s]);
    return ok_status();
  }));
  for (std::vector<Timestamp>& sensor_times : times) std::sort(sensor_times.begin(), sensor_times.end());
  DatasetExportSummary summary;
  summary.reference_messages = times[*reference].size();
  if (times[*reference].empty()) {
    return Error(fmt::format("{}: no message of the reference sensor '{}' (topic {})", log_path, sensors[*reference].name,
                             config.sensors[*reference].topic));
  }

  // The frames.
  const TrajectoryInterpolator poses(trajectory, config.max_trajectory_gap_s);
  const Duration max_difference = Duration::from_seconds(config.max_time_difference_s);
  const bool need_all = config.layout == DatasetLayout::kKittiOdometry || config.require_all_sensors;
  std::vector<PlannedFrame> planned;
  std::map<std::pair<std::size_t, Timestamp>, std::vector<std::size_t>> frames_of_message;  // (sensor, time) -> frames
  for (std::size_t i = 0; i < times[*reference].size(); i += static_cast<std::size_t>(config.every)) {
    const Timestamp time = times[*reference][i];
    const std::optional<SE3> pose = poses.at(time);
    if (!pose) {
      ++summary.outside_trajectory;
      continue;
    }
    PlannedFrame frame{time, *pose, std::vector<std::optional<Timestamp>>(sensors.size())};
    bool complete = true;
    for (std::size_t s = 0; s < sensors.size(); ++s) {
      frame.message_times[s] = s == *reference ? std::optional<Timestamp>(time) : nearest(times[s], time, max_difference);
      if (frame.message_times[s] && !poses.at(*frame.message_times[s])) frame.message_times[s].reset();
      complete = complete && frame.message_times[s].has_value();
    }
    if (!complete && need_all) {
      ++summary.missing_sensor;
      continue;
    }
    for (std::size_t s = 0; s < sensors.size(); ++s) {
      if (frame.message_times[s]) frames_of_message[{s, *frame.message_times[s]}].push_back(planned.size());
    }
    planned.push_back(std::move(frame));
  }
  if (planned.empty()) {
    return Error(fmt::format("no frame to export: of {} messages of '{}', {} are outside the trajectory ({:.3f} .. {:.3f} s) and {} lack "
                             "another sensor's message within {} s",
                             summary.reference_messages, sensors[*reference].name, summary.outside_trajectory,
                             trajectory.timestamps.front().seconds(), trajectory.timestamps.back().seconds(), summary.missing_sensor,
                             config.max_time_difference_s));
  }

  // The output folder: new or empty.
  std::error_code error;
  if (std::filesystem::exists(out_dir, error) && !std::filesystem::is_empty(out_dir, error)) {
    return Error(fmt::format("{}: the folder exists and is not empty", out_dir));
  }
  std::filesystem::create_directories(out_dir, error);
  if (error) return Error(fmt::format("{}: cannot create the folder ({})", out_dir, error.message()));
  std::vector<LayoutFrame> frames;
  for (const PlannedFrame& frame : planned) frames.push_back({frame.time, frame.T_world_body});
  std::unique_ptr<dataset::DatasetLayoutWriter> writer =
      config.layout == DatasetLayout::kKittiOdometry ? dataset::make_kitti_writer(out_dir, sensors, frames)
                                                     : dataset::make_nuscenes_writer(out_dir, sensors, frames, config);

  // Pass 2: the data.
  std::map<std::size_t, UndistortMaps> undistort_cache;
  Status written = visit_sensor_messages(log_path, sensor_by_topic, [&](std::size_t s, const std::string&, const msgs::SensorMessage& message) -> Status {
    const Timestamp time = msgs::timestamp_of(message) + time_offsets[s];
    const auto uses = frames_of_message.find({s, time});
    if (uses == frames_of_message.end()) return ok_status();
    const SE3 T_world_body = *poses.at(time);
    if (const auto* cloud = std::get_if<msgs::PointCloudMessage>(&message)) {
      LayoutCloud out{cloud->points, cloud->intensities, cloud->ring_ids};
      if (config.deskew && !cloud->point_timestamps.empty()) {
        out = deskewed(*cloud, poses, sensors[s].T_body_sensor, time_offsets[s]);
        ++summary.deskewed_sweeps;
      }
      for (const std::size_t frame : uses->second) HANZO_RETURN_IF_ERROR(writer->write_cloud(frame, s, time, T_world_body, out));
    } else {
      msgs::ImageMessage image = std::get<msgs::ImageMessage>(message);
      const msgs::CameraIntrinsics& intrinsics = sensors[s].intrinsics;
      if (intrinsics.width != 0 && (intrinsics.width != image.width || intrinsics.height != image.height)) {
        return Error(fmt::format("{}: image of {} at {:.6f} s is {}x{}, its calibration says {}x{}", log_path, sensors[s].name, time.seconds(),
                                 image.width, image.height, intrinsics.width, intrinsics.height));
      }
      if (cameras[s]->distortion != PinholeCamera::Distortion::kNone) {
        auto maps = undistort_cache.find(s);
        if (maps == undistort_cache.end()) {
          maps = undistort_cache.emplace(s, undistort_maps(*cameras[s], static_cast<int>(image.width), static_cast<int>(image.height))).first;
        }
        if (maps->second.map_x.cols != static_cast<int>(image.width) || maps->second.map_x.rows != static_cast<int>(image.height)) {
          return Error(fmt::format("{}: images of {} change size ({}x{} at {:.6f} s)", log_path, sensors[s].name, image.width, image.height,
                                   time.seconds()));
        }
        image = undistorted(image, maps->second);
        ++summary.undistorted_images;
      }
      for (const std::size_t frame : uses->second) HANZO_RETURN_IF_ERROR(writer->write_image(frame, s, time, T_world_body, image));
    }
    summary.files_by_sensor[sensors[s].name] += uses->second.size();
    return ok_status();
  });
  if (written) written = writer->finish();
  if (!written) {
    writer.reset();
    std::filesystem::remove_all(out_dir, error);
    return written.error();
  }
  summary.frames = planned.size();
  summary.bytes_written = writer->bytes_written();
  summary.first_frame_time_s = planned.front().time.seconds();
  summary.last_frame_time_s = planned.back().time.seconds();
  logger()->info("export dataset: {} frames into {} ({} MB)", summary.frames, out_dir, summary.bytes_written / 1000000);
  return summary;
}

}  // namespace hanzo::fusion::io
