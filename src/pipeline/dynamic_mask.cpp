#include "hanzo/fusion/pipeline/dynamic_mask.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::pipeline {
namespace {

constexpr int kMinSegmentWidth = 5;  // pixels

}  // namespace

bool is_dynamic_class(std::string_view class_name, const config::DynamicObjectsConfig& config) {
  const auto same = [class_name](const std::string& name) {
    return name.size() == class_name.size() && std::equal(name.begin(), name.end(), class_name.begin(), [](char a, char b) {
             return std::tolower(static_cast<unsigned char>(a)) == std::tolower(static_cast<unsigned char>(b));
           });
  };
  return std::any_of(config.classes.begin(), config.classes.end(), same);
}

Result<DynamicMask> dynamic_mask(const msgs::DetectionsMessage& detections, cv::Size image_size, const config::DynamicObjectsConfig& config) {
  if (static_cast<int>(detections.image_width) != image_size.width || static_cast<int>(detections.image_height) != image_size.height) {
    return Error(fmt::format("detections for a {} x {} image, the camera's images are {} x {}", detections.image_width, detections.image_height,
                             image_size.width, image_size.height),
                 "image_width");
  }
  DynamicMask result;
  cv::Mat objects;  // 255 on the moving objects
  const int margin = static_cast<int>(std::ceil(config.margin_px));
  cv::Mat instances;  // instance masks before their dilation
  for (const msgs::Detection2D& detection : detections.detections) {
    if (detection.score < config.min_score || !is_dynamic_class(detection.class_name, config)) continue;
    if (objects.empty()) objects = cv::Mat::zeros(image_size, CV_8UC1);
    ++result.masked_objects;
    // The box's pixels: centres from ceil(min) to floor(max).
    const int x0 = std::max(0, static_cast<int>(std::ceil(detection.x_min))), y0 = std::max(0, static_cast<int>(std::ceil(detection.y_min)));
    const int x1 = std::min(image_size.width - 1, static_cast<int>(std::floor(detection.x_max)));
    const int y1 = std::min(image_size.height - 1, static_cast<int>(std::floor(detection.y_max)));
    if (x1 < x0 || y1 < y0) continue;
    if (detection.mask.empty()) {
      const cv::Rect grown(cv::Point(x0 - margin, y0 - margin), cv::Point(x1 + margin + 1, y1 + margin + 1));
      objects(grown & cv::Rect(cv::Point(0, 0), image_size)).setTo(255);
      continue;
    }
    if (instances.empty()) instances = cv::Mat::zeros(image_size, CV_8UC1);
    const cv::Mat mask(static_cast<int>(detection.mask_height), static_cast<int>(detection.mask_width), CV_8UC1,
                       const_cast<uint8_t*>(detection.mask.data()));
    cv::Mat stretched;
    cv::resize(mask, stretched, cv::Size(x1 - x0 + 1, y1 - y0 + 1), 0.0, 0.0, cv::INTER_NEAREST);
    cv::Mat target = instances(cv::Rect(x0, y0, x1 - x0 + 1, y1 - y0 + 1));
    target.setTo(255, stretched);
  }
  // The segmentation's pixels of moving classes, as instance masks.
  std::array<bool, 256> dynamic_ids{};
  bool any_dynamic_id = false;
  for (std::size_t id = 0; id < detections.segmentation_classes.size() && id < dynamic_ids.size(); ++id) {
    dynamic_ids[id] = is_dynamic_class(detections.segmentation_classes[id], config);
    any_dynamic_id = any_dynamic_id || dynamic_ids[id];
  }
  if (any_dynamic_id && detections.segmentation.size() == static_cast<std::size_t>(image_size.area())) {
    cv::Mat segmented = cv::Mat::zeros(image_size, CV_8UC1);
    for (std::size_t pixel = 0; pixel < detections.segmentation.size(); ++pixel) {
      if (dynamic_ids[detections.segmentation[pixel]]) segmented.data[pixel] = 255;
    }
    // A segmenter's scattered wrong pixels are no object: an opening keeps regions at least
    // kMinSegmentWidth pixels across.
    cv::morphologyEx(segmented, segmented, cv::MORPH_OPEN, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(kMinSegmentWidth, kMinSegmentWidth)));
    if (cv::countNonZero(segmented) > 0) {
      instances = instances.empty() ? segmented : (instances | segmented);
      if (objects.empty()) objects = cv::Mat::zeros(image_size, CV_8UC1);
    }
  }
  if (objects.empty()) return result;
  if (!instances.empty()) {
    if (margin > 0) cv::dilate(instances, instances, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * margin + 1, 2 * margin + 1)));
    objects |= instances;
  }
  result.masked_share = static_cast<double>(cv::countNonZero(objects)) / static_cast<double>(image_size.area());
  cv::bitwise_not(objects, result.static_mask);
  return result;
}

}  // namespace hanzo::fusion::pipeline
