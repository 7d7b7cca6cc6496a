#pragma once
// The static mask of a camera image from a detector's output (msgs::DetectionsMessage): where
// the visual odometry may take features (non-zero) and where a moving object is (zero).
//
// A detection masks when its class is one of config.classes (without regard to case) and its
// score is at least config.min_score: its box grown by config.margin_px on every side, or,
// with an instance mask, the mask's pixels (stretched over the box, nearest neighbour) dilated
// by config.margin_px. Boxes are in pixels, integer coordinates at pixel centres. A dense
// segmentation's pixels of those classes mask as an instance mask does (dilated by margin_px),
// after an opening with a 5-pixel disc (scattered wrong pixels of a segmenter mask nothing).
//
// Failures: detections for another image size than the camera's (the boxes would land in the
// wrong place) are refused, naming both sizes.

#include <string_view>

#include <opencv2/core.hpp>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::pipeline {

struct DynamicMask {
  cv::Mat static_mask;       ///< CV_8UC1 of the image's size, 0 on moving objects; empty when nothing masks
  int masked_objects = 0;    ///< detections that masked
  double masked_share = 0.0; ///< of the image's pixels, [0, 1]
};

/// Whether a detection's class is one that moves (config.classes, any case).
bool is_dynamic_class(std::string_view class_name, const config::DynamicObjectsConfig& config);

Result<DynamicMask> dynamic_mask(const msgs::DetectionsMessage& detections, cv::Size image_size, const config::DynamicObjectsConfig& config);

}  // namespace hanzo::fusion::pipeline
