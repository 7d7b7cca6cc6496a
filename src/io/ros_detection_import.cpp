#include "ros_detection_import.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::io::ros {
namespace {

// Class ids a segmentation holds: 0 .. 253 (msgs::kUnlabelledPixel is 255; validate.hpp).
constexpr uint32_t kClasses = msgs::kUnlabelledPixel - 1;

std::optional<uint64_t> decimal(const std::string& text) {
  if (text.empty() || text.size() > 18 || !std::all_of(text.begin(), text.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    return std::nullopt;
  }
  return std::strtoull(text.c_str(), nullptr, 10);
}

std::string class_name(const std::string& class_id, const LabelTable* labels) {
  if (labels == nullptr) return class_id;
  const std::optional<uint64_t> id = decimal(class_id);
  if (!id || *id > 0xFFFF) return class_id;
  const auto named = labels->class_names.find(static_cast<uint16_t>(*id));
  return named != labels->class_names.end() ? named->second : class_id;
}

}  // namespace

int64_t TrackIds::track_id(const std::string& id) {
  if (id.empty()) return -1;
  if (const std::optional<uint64_t> number = decimal(id)) return static_cast<int64_t>(*number);
  return named_.emplace(id, static_cast<int64_t>(named_.size())).first->second;
}

Result<std::vector<msgs::Detection2D>> boxes_in_image(const RosDetections& array, const LabelTable* labels, uint32_t width,
                                                      uint32_t height, TrackIds& track_ids) {
  // Pixel centres are integers: the image spans [-0.5, size - 0.5].
  const double right = width - 0.5, bottom = height - 0.5;
  std::vector<msgs::Detection2D> boxes;
  boxes.reserve(array.detections.size());
  for (std::size_t i = 0; i < array.detections.size(); ++i) {
    const RosDetection& in = array.detections[i];
    const double c = std::abs(std::cos(in.theta)), s = std::abs(std::sin(in.theta));
    const double half_x = 0.5 * (c * in.size_x + s * in.size_y), half_y = 0.5 * (s * in.size_x + c * in.size_y);
    if (!std::isfinite(in.center_x) || !std::isfinite(in.center_y) || !std::isfinite(half_x) || !std::isfinite(half_y) || half_x < 0.0 ||
        half_y < 0.0) {
      return Error(fmt::format("detections[{}]: box centre ({}, {}) size {} x {} is not a box", i, in.center_x, in.center_y, in.size_x, in.size_y));
    }
    msgs::Detection2D box;
    box.class_name = class_name(in.class_id, labels);
    box.score = static_cast<float>(in.score);
    box.x_min = static_cast<float>(std::max(-0.5, in.center_x - half_x));
    box.y_min = static_cast<float>(std::max(-0.5, in.center_y - half_y));
    box.x_max = static_cast<float>(std::min(right, in.center_x + half_x));
    box.y_max = static_cast<float>(std::min(bottom, in.center_y + half_y));
    if (box.x_min > box.x_max || box.y_min > box.y_max) {
      return Error(fmt::format("detections[{}]: box centre ({}, {}) size {} x {} lies outside the {} x {} image", i, in.center_x, in.center_y,
                               in.size_x, in.size_y, width, height));
    }
    box.track_id = track_ids.track_id(in.id);
    boxes.push_back(std::move(box));
  }
  return boxes;
}

Result<Segmentation> segmentation_in_image(const msgs::ImageMessage& label_image, const LabelTable* labels, uint32_t width, uint32_t height) {
  const bool wide = label_image.encoding == msgs::ImageEncoding::kDepth16;
  if (label_image.encoding != msgs::ImageEncoding::kMono8 && !wide) {
    return Error(fmt::format("a label image must be mono8 / 8UC1 or 16UC1 / mono16 class ids, not {}", msgs::to_string(label_image.encoding)));
  }
  const double aspect_in = static_cast<double>(label_image.width) / label_image.height;
  const double aspect_camera = static_cast<double>(width) / height;
  if (std::abs(aspect_in / aspect_camera - 1.0) > 0.01) {
    return Error(fmt::format("a {} x {} label image does not cover the camera's {} x {} images", label_image.width, label_image.height, width, height));
  }
  cv::Mat ids(static_cast<int>(label_image.height), static_cast<int>(label_image.width), CV_8UC1);
  uint8_t largest = 0;
  for (std::size_t i = 0; i < ids.total(); ++i) {
    uint32_t id = label_image.data[i];
    if (wide) {
      uint16_t value = 0;
      std::memcpy(&value, label_image.data.data() + 2 * i, 2);
      id = value == 0xFFFF ? msgs::kUnlabelledPixel : value;
    }
    if (id >= kClasses && id != msgs::kUnlabelledPixel) {
      return Error(fmt::format("pixel ({}, {}) has class id {}: a segmentation holds class ids 0 to {} (255: unlabelled)", i % label_image.width,
                               i / label_image.width, id, kClasses - 1));
    }
    ids.data[i] = static_cast<uint8_t>(id);
    if (id != msgs::kUnlabelledPixel) largest = std::max(largest, static_cast<uint8_t>(id));
  }
  if (ids.cols != static_cast<int>(width) || ids.rows != static_cast<int>(height)) {
    cv::Mat scaled;
    cv::resize(ids, scaled, cv::Size(static_cast<int>(width), static_cast<int>(height)), 0.0, 0.0, cv::INTER_NEAREST);
    ids = scaled;
  }
  Segmentation segmentation;
  segmentation.class_ids.assign(ids.data, ids.data + ids.total());
  std::size_t classes = static_cast<std::size_t>(largest) + 1;
  if (labels != nullptr) {
    for (const auto& [id, name] : labels->class_names) {
      if (id < kClasses) classes = std::max(classes, static_cast<std::size_t>(id) + 1);
    }
  }
  for (std::size_t id = 0; id < classes; ++id) {
    std::string name = std::to_string(id);
    if (labels != nullptr) {
      if (const auto named = labels->class_names.find(static_cast<uint16_t>(id)); named != labels->class_names.end()) name = named->second;
    }
    segmentation.classes.push_back(std::move(name));
  }
  return segmentation;
}

std::vector<ReadyDetections> DetectionMerger::add(const std::string& source, const DetectionCamera& camera, Timestamp stamp,
                                                  const std::string& frame_id, std::vector<msgs::Detection2D> boxes,
                                                  std::optional<Segmentation> segmentation) {
  unattached_.erase(source);
  sources_of_camera_[camera.log_topic].insert(source);
  Timestamp& latest = latest_of_source_[source];
  latest = std::max(latest, stamp);
  Pending& pending = pending_[camera.log_topic][stamp];
  msgs::DetectionsMessage& message = pending.ready.message;
  if (pending.sources.empty()) {
    pending.ready.log_topic = camera.log_topic + "/detections";
    pending.ready.sensor_name = camera.sensor_name;
    pending.ready.source = source;
    message.timestamp = stamp;
    message.frame_id = frame_id;
    message.image_width = camera.width;
    message.image_height = camera.height;
  }
  pending.sources.insert(source);
  message.detections.insert(message.detections.end(), std::make_move_iterator(boxes.begin()), std::make_move_iterator(boxes.end()));
  if (segmentation && message.segmentation.empty()) {  // a second segmenter of the same image: the first one's labels are kept
    message.segmentation = std::move(segmentation->class_ids);
    message.segmentation_classes = std::move(segmentation->classes);
  }
  return take_complete(camera.log_topic);
}

std::vector<ReadyDetections> DetectionMerger::take_complete(const std::string& camera_topic) {
  std::vector<ReadyDetections> ready;
  std::map<Timestamp, Pending>& pending = pending_[camera_topic];
  if (pending.empty()) return ready;
  const Timestamp newest = pending.rbegin()->first;
  const auto done = [&](const std::pair<const Timestamp, Pending>& image, const std::string& source) {
    const auto latest = latest_of_source_.find(source);
    return image.second.sources.count(source) != 0 || (latest != latest_of_source_.end() && latest->second > image.first);
  };
  const std::set<std::string>& attached = sources_of_camera_[camera_topic];
  for (auto it = pending.begin(); it != pending.end();) {
    const bool complete = (newest - it->first).seconds() > kMaxLag_s ||
                          (std::all_of(attached.begin(), attached.end(), [&](const std::string& source) { return done(*it, source); }) &&
                           std::all_of(unattached_.begin(), unattached_.end(), [&](const std::string& source) { return done(*it, source); }));
    if (!complete) break;  // later images wait for this one: the log keeps each camera's detections in time order
    ready.push_back(std::move(it->second.ready));
    it = pending.erase(it);
  }
  return ready;
}

std::vector<ReadyDetections> DetectionMerger::flush() {
  std::vector<ReadyDetections> ready;
  for (auto& [camera, pending] : pending_) {
    for (auto& [stamp, open] : pending) ready.push_back(std::move(open.ready));
    pending.clear();
  }
  return ready;
}

}  // namespace hanzo::fusion::io::ros
