#include "hanzo/fusion/neural/log_views.hpp"

#include <algorithm>
#include <cmath>
#include <set>

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "view_images.hpp"

namespace hanzo::fusion::neural {

namespace {

/// T_world_body at `time`, interpolated; none outside the trajectory or across a gap.
std::optional<SE3> pose_at(const io::Trajectory& trajectory, Timestamp time, double max_gap) {
  const auto after = std::lower_bound(trajectory.timestamps.begin(), trajectory.timestamps.end(), time);
  if (after == trajectory.timestamps.end()) return std::nullopt;
  const auto i = static_cast<std::size_t>(after - trajectory.timestamps.begin());
  if (*after == time) return trajectory.pose_se3(i);
  if (i == 0) return std::nullopt;
  const double span = (trajectory.timestamps[i] - trajectory.timestamps[i - 1]).seconds();
  const double since = (time - trajectory.timestamps[i - 1]).seconds();
  if (std::min(since, span - since) > max_gap) return std::nullopt;
  return SE3::interpolate(trajectory.pose_se3(i - 1), trajectory.pose_se3(i), since / span);
}

/// The message's pixels as an 8-bit OpenCV image (BGR or grey).
Result<cv::Mat> to_mat(const msgs::ImageMessage& image) {
  const int rows = static_cast<int>(image.height), cols = static_cast<int>(image.width);
  switch (image.encoding) {
    case msgs::ImageEncoding::kMono8:
      if (image.data.size() != static_cast<std::size_t>(rows) * static_cast<std::size_t>(cols)) break;
      return cv::Mat(rows, cols, CV_8UC1, const_cast<uint8_t*>(image.data.data())).clone();
    case msgs::ImageEncoding::kRgb8:
    case msgs::ImageEncoding::kBgr8: {
      if (image.data.size() != 3 * static_cast<std::size_t>(rows) * static_cast<std::size_t>(cols)) break;
      cv::Mat bgr = cv::Mat(rows, cols, CV_8UC3, const_cast<uint8_t*>(image.data.data())).clone();
      if (image.encoding == msgs::ImageEncoding::kRgb8) cv::cvtColor(bgr, bgr, cv::COLOR_RGB2BGR);
      return bgr;
    }
    default:
      return Error("not a colour or grey image (depth images are not views)");
  }
  return Error(fmt::format("{} bytes do not fill {} x {}", image.data.size(), cols, rows));
}

}  // namespace

void place_camera(SplatCamera& camera, const SE3& T_world_camera) {
  const SE3 T_camera_world = T_world_camera.inverse();
  camera.R_camera_world = T_camera_world.rotation().matrix();
  camera.t_camera_world = T_camera_world.translation();
}

Result<PosedView> image_view(const msgs::ImageMessage& image, const msgs::CameraIntrinsics& intrinsics, const msgs::DistortionModel& distortion,
                             const SE3& T_world_camera, int downscale) {
  if (downscale < 1) return Error(fmt::format("image_view: downscale {} is not >= 1", downscale));
  if (intrinsics.width != 0 && (image.width != intrinsics.width || image.height != intrinsics.height)) {
    return Error(fmt::format("image at {} is {} x {}, the camera {} x {}", image.timestamp.to_iso8601(), image.width, image.height, intrinsics.width,
                             intrinsics.height));
  }
  cv::Mat read;
  HANZO_ASSIGN_OR_RETURN(read, to_mat(image));
  const cv::Matx33d k(intrinsics.fx, 0, intrinsics.cx, 0, intrinsics.fy, intrinsics.cy, 0, 0, 1);
  if (distortion.type == msgs::DistortionType::kRadtan) {
    cv::Mat undistorted;
    cv::undistort(read, undistorted, k, distortion.coefficients, k);
    read = undistorted;
  } else if (distortion.type == msgs::DistortionType::kEquidistant) {
    cv::Mat undistorted;
    cv::fisheye::undistortImage(read, undistorted, k, distortion.coefficients, k);
    read = undistorted;
  }
  PosedView view;
  ViewDatasetConfig image_config;
  image_config.downscale = downscale;
  HANZO_RETURN_IF_ERROR(to_view_image(read, image_config, view));
  const double s = static_cast<double>(downscale);
  view.camera.width = view.image.width;
  view.camera.height = view.image.height;
  view.camera.fx = intrinsics.fx / s;
  view.camera.fy = intrinsics.fy / s;
  view.camera.cx = (intrinsics.cx + 0.5) / s - 0.5;
  view.camera.cy = (intrinsics.cy + 0.5) / s - 0.5;
  place_camera(view.camera, T_world_camera);
  return view;
}

Result<LogViews> load_log_views(const std::string& log_path, const std::string& trajectory_path, const std::string& calibration_path,
                                const LogViewsConfig& config) {
  if (config.downscale < 1 || config.max_views < 1 || !(config.min_translation >= 0.0) || !(config.min_rotation_degrees >= 0.0) || !(config.max_gap > 0.0)) {
    return Error("LogViewsConfig: downscale and max_views must be >= 1, min_translation and min_rotation_degrees >= 0, max_gap > 0");
  }
  calib::Calibration calibration;
  HANZO_ASSIGN_OR_RETURN(calibration, calib::load_calibration(calibration_path));
  const calib::SensorCalibration* camera = nullptr;
  for (const calib::SensorCalibration& sensor : calibration.sensors) {
    if (sensor.camera && (config.camera.empty() || sensor.sensor == config.camera)) {
      camera = &sensor;
      break;
    }
  }
  if (camera == nullptr) {
    return Error(config.camera.empty() ? fmt::format("{}: no camera (no entry with intrinsics)", calibration_path)
                                       : fmt::format("{}: no camera '{}' (with intrinsics)", calibration_path, config.camera));
  }
  io::Trajectory trajectory;
  HANZO_ASSIGN_OR_RETURN(trajectory, io::read_trajectory(trajectory_path, io::TrajectoryFormat::kTum));
  if (trajectory.size() < 2) return Error(fmt::format("{}: fewer than two poses", trajectory_path));
  std::unique_ptr<io::SensorLogReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, io::SensorLogReader::open(log_path));

  LogViews result;
  result.topic = config.topic.empty() ? "/sensors/" + camera->sensor : config.topic;
  const SE3 T_body_camera = camera->T_body_sensor();
  const msgs::CameraIntrinsics& intrinsics = camera->camera->intrinsics;
  const msgs::DistortionModel& distortion = camera->camera->distortion;
  std::set<std::string> image_topics;
  std::vector<PosedView> views;
  std::optional<SE3> last_kept;
  io::LogEntry entry;
  while (true) {
    Result<bool> more = reader->next(entry);
    if (!more) return Error(fmt::format("{}: {}", log_path, more.error().message));
    if (!*more) break;
    const auto* image = std::get_if<msgs::SensorMessage>(&entry.message);
    const auto* message = image != nullptr ? std::get_if<msgs::ImageMessage>(image) : nullptr;
    if (message == nullptr || message->encoding == msgs::ImageEncoding::kDepth16 || message->encoding == msgs::ImageEncoding::kDepth32f) continue;
    image_topics.insert(entry.topic);
    if (entry.topic != result.topic) continue;
    ++result.images;
    const std::optional<SE3> T_world_body = pose_at(trajectory, message->timestamp + camera->time_offset, config.max_gap);
    if (!T_world_body) {
      ++result.outside_trajectory;
      continue;
    }
    const SE3 T_world_camera = *T_world_body * T_body_camera;
    if (last_kept) {
      const SE3 motion = last_kept->inverse() * T_world_camera;
      const double degrees = motion.rotation().log().norm() * 180.0 / M_PI;
      if (motion.translation().norm() < config.min_translation && degrees < config.min_rotation_degrees) continue;
    }
    Result<PosedView> converted = image_view(*message, intrinsics, distortion, T_world_camera, config.downscale);
    if (!converted) return Error(fmt::format("{}: {}: {}", log_path, entry.topic, converted.error().message));
    PosedView view = std::move(converted).value();
    view.name = fmt::format("{}@{}", entry.topic, message->timestamp.to_iso8601());
    views.push_back(std::move(view));
    last_kept = T_world_camera;
  }
  if (result.images == 0) {
    return Error(fmt::format("{}: no images on {} (image topics: {})", log_path, result.topic,
                             image_topics.empty() ? std::string("none") : fmt::format("{}", fmt::join(image_topics, ", "))));
  }
  if (views.empty()) return Error(fmt::format("{}: none of the {} images on {} lies inside {}'s span", log_path, result.images, result.topic, trajectory_path));
  // Evenly thinned to max_views.
  if (views.size() > static_cast<std::size_t>(config.max_views)) {
    std::vector<PosedView> thinned;
    for (int i = 0; i < config.max_views; ++i) thinned.push_back(std::move(views[static_cast<std::size_t>(i) * views.size() / static_cast<std::size_t>(config.max_views)]));
    views = std::move(thinned);
  }
  result.dataset.views = std::move(views);
  set_scene_extent(result.dataset);
  // The box: the cameras' positions grown by the distance they see the scene at (their mean
  // distance from where their axes meet, at most the positions' own extent).
  Eigen::Vector3d low = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), high = -low;
  for (const PosedView& view : result.dataset.views) {
    low = low.cwiseMin(view.camera.centre_world());
    high = high.cwiseMax(view.camera.centre_world());
  }
  const double reach = std::min(result.dataset.camera_distance, std::max(1.0, (high - low).maxCoeff()));
  result.dataset.box_centre = 0.5 * (low + high);
  result.dataset.box_half_size = 0.5 * (high - low).maxCoeff() + reach;
  return result;
}

}  // namespace hanzo::fusion::neural
