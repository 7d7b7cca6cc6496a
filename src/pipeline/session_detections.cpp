// Session: a detector's output on the cameras (msgs::DetectionsMessage): the dynamic masks it
// gives the visual odometry (fusion.vision.dynamic_objects; session.hpp, dynamic_mask.hpp), its
// segmentation classes and moving objects on the 3D LiDAR's points (semantic_projection.hpp);
// the Session's own detector (fusion.vision.detector) on cameras without such output.

#include <algorithm>
#include <chrono>
#include <cmath>

#include <fmt/format.h>

#include "camera_odometry.hpp"
#include "semantic_projection.hpp"
#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/msgs/validate.hpp"
#include "hanzo/fusion/pipeline/camera_detector.hpp"
#include "hanzo/fusion/pipeline/dynamic_mask.hpp"
#include "hanzo/fusion/pipeline/session.hpp"

namespace hanzo::fusion::pipeline {
namespace {

// A detector stamps its output with its image's timestamp; this much apart still matches.
constexpr double kMatchTolerance_s = 1e-3;
// Detections kept per camera while their images have not come (a detector ahead of the images).
constexpr std::size_t kRecentDetections = 16;

bool same_time(Timestamp a, Timestamp b) { return std::abs((a - b).seconds()) <= kMatchTolerance_s; }

}  // namespace

PushStatus Session::push_detections(std::string_view sensor, const msgs::DetectionsMessage& detections) {
  return use_detections(sensor, detections, false);
}

void Session::detect_objects(std::string_view sensor, const msgs::SensorMessage& message) {
  const auto* image = std::get_if<msgs::ImageMessage>(&message);
  if (image == nullptr || !msgs::validate(*image).ok()) return;  // refused where the image goes
  const bool tracked = camera_odometry_ && camera_odometry_->handles(sensor);
  if (!tracked && (semantic_projection_ == nullptr || semantic_projection_->camera(sensor) == nullptr)) return;
  if (const auto camera = camera_detections_.find(sensor); camera != camera_detections_.end() && camera->second.external) return;
  const auto start = std::chrono::steady_clock::now();
  Result<msgs::DetectionsMessage> detections = detector_->detect(*image);
  detector_ms_sum_ += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  ++summary_.detections_computed;
  if (!detections) {
    ++summary_.detector_failures;
    logger()->warn("session: {}: the object detector failed on the image at {:.3f} s: {}", sensor, image->timestamp.seconds(), detections.error().message);
    return;
  }
  (void)use_detections(sensor, *detections, true);  // counted like pushed ones
}

PushStatus Session::use_detections(std::string_view sensor, const msgs::DetectionsMessage& detections, bool computed) {
  ++summary_.detections_received;
  const auto refuse = [this](Rejection reason, const std::string& detail) {
    ++summary_.detections_refused;
    return PushStatus(reason, detail);
  };
  const bool tracked = camera_odometry_ && camera_odometry_->handles(sensor);
  const SemanticProjection::Camera* projected = semantic_projection_ ? semantic_projection_->camera(sensor) : nullptr;
  if (!tracked && projected == nullptr) {
    return refuse(Rejection::kWrongType,
                  fmt::format("{}: detections for a sensor that is not a camera of the visual odometry or one with a lens model beside a 3D LiDAR", sensor));
  }
  if (Status valid = msgs::validate(detections); !valid) return refuse(Rejection::kInvalid, fmt::format("{}: {}", sensor, valid.error().message));
  const cv::Size image_size = tracked ? camera_odometry_->rig_of(sensor)->image_size : projected->image_size;
  if (static_cast<int>(detections.image_width) != image_size.width || static_cast<int>(detections.image_height) != image_size.height) {
    return refuse(Rejection::kInvalid, fmt::format("{}: detections for a {} x {} image, the camera's images are {} x {}", sensor, detections.image_width,
                                                   detections.image_height, image_size.width, image_size.height));
  }
  if (!computed) camera_detections_[std::string(sensor)].external = true;
  if (projected != nullptr) {
    semantic_projection_->add(*projected, detections, [this](std::string_view name) { return map_builder_.class_index(name); });
  }
  if (!tracked) return {};
  CameraDetections& camera = camera_detections_[std::string(sensor)];
  camera.streaming = true;
  if (camera.last_image_time && detections.timestamp <= *camera.last_image_time + Duration::from_seconds(kMatchTolerance_s) &&
      !(camera.waiting && same_time(camera.waiting->timestamp, detections.timestamp))) {
    // Its image was tracked without it.
    ++summary_.detections_late;
    logger()->debug("session: {}: detections at {:.3f} s came after their image", sensor, detections.timestamp.seconds());
    return {};
  }
  camera.recent.push_back(detections);
  if (camera.recent.size() > kRecentDetections) camera.recent.pop_front();
  if (camera.waiting && same_time(camera.waiting->timestamp, detections.timestamp)) {
    msgs::ImageMessage image = std::move(*camera.waiting);
    camera.waiting.reset();
    (void)track_image(std::string(sensor), image);  // its outcome is counted in the camera's statistics
  }
  return {};
}

bool Session::wait_for_detections(std::string_view sensor, Timestamp time) {
  if (!frontend_->config().vision.dynamic_objects.wait_for_detections) return false;
  const auto camera = camera_detections_.find(sensor);
  if (camera == camera_detections_.end() || !camera->second.streaming) return false;  // no detector on this camera (yet)
  return std::none_of(camera->second.recent.begin(), camera->second.recent.end(),
                      [time](const msgs::DetectionsMessage& detections) { return same_time(detections.timestamp, time); });
}

void Session::release_waiting_images(std::optional<Timestamp> before) {
  for (auto& [sensor, camera] : camera_detections_) {
    if (!camera.waiting || (before && camera.waiting->timestamp + Duration::from_seconds(kMatchTolerance_s) >= *before)) continue;
    msgs::ImageMessage image = std::move(*camera.waiting);
    camera.waiting.reset();
    ++summary_.images_without_detections;
    (void)track_image(sensor, image);
  }
}

vision::StaticMask Session::static_mask_for(const std::string& sensor, const msgs::ImageMessage& image) {
  const auto camera = camera_detections_.try_emplace(sensor).first;
  camera->second.last_image_time = image.timestamp;
  std::deque<msgs::DetectionsMessage>& recent = camera->second.recent;
  const auto match = std::find_if(recent.begin(), recent.end(), [&image](const msgs::DetectionsMessage& d) { return same_time(d.timestamp, image.timestamp); });
  if (match == recent.end()) {
    std::erase_if(recent, [&image](const msgs::DetectionsMessage& d) { return d.timestamp < image.timestamp; });
    return {};
  }
  ++summary_.detections_matched;
  Result<DynamicMask> mask = dynamic_mask(*match, cv::Size(static_cast<int>(image.width), static_cast<int>(image.height)), frontend_->config().vision.dynamic_objects);
  // Those of this image and older are done.
  std::erase_if(recent, [&image](const msgs::DetectionsMessage& d) { return d.timestamp <= image.timestamp + Duration::from_seconds(kMatchTolerance_s); });
  if (!mask) {
    logger()->warn("session: {}: detections at {:.3f} s not used: {}", sensor, image.timestamp.seconds(), mask.error().message);
    return {};
  }
  if (mask->static_mask.empty()) return {};
  ++summary_.images_masked;
  summary_.dynamic_objects_masked += static_cast<uint64_t>(mask->masked_objects);
  masked_share_sum_ += mask->masked_share;
  return {mask->static_mask};
}

void Session::mask_moving_points(LidarInertialOdometry::PreparedScan& prepared) {
  const SemanticProjection::Labelled labelled =
      semantic_projection_->label(prepared.time, prepared.cloud.positions, [this](Timestamp at) { return frontend_->pose_at(at); });
  if (labelled.moving_points == 0) return;
  std::vector<uint32_t> kept;
  kept.reserve(prepared.cloud.size() - labelled.moving_points);
  for (std::size_t i = 0; i < prepared.cloud.size(); ++i) {
    if (labelled.moving[i] == 0) kept.push_back(static_cast<uint32_t>(i));
  }
  prepared.cloud = cloud::select(prepared.cloud, kept);
  summary_.lidar_points_masked += labelled.moving_points;
}

std::pair<std::vector<Eigen::Vector3f>, std::vector<uint16_t>> Session::label_sweep(Timestamp time, const std::vector<Eigen::Vector3f>& points) {
  if (!semantic_projection_) return {points, {}};
  const SemanticProjection::Labelled labelled =
      semantic_projection_->label(time, points, [this](Timestamp at) { return frontend_->pose_at(at); });
  summary_.lidar_points_labelled += labelled.labelled;
  summary_.lidar_points_masked += labelled.moving_points;
  if (labelled.labelled == 0 && labelled.moving_points == 0) return {points, {}};
  std::pair<std::vector<Eigen::Vector3f>, std::vector<uint16_t>> kept;
  kept.first.reserve(points.size());
  if (labelled.labelled > 0) kept.second.reserve(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (labelled.moving[i] != 0) continue;
    kept.first.push_back(points[i]);
    if (labelled.labelled > 0) kept.second.push_back(labelled.classes[i]);
  }
  return kept;
}

}  // namespace hanzo::fusion::pipeline
