#pragma once
// A sensor message's image as the 8-bit grey cv::Mat the vision module works on, or in colour.

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::vision {

/// The image as 8-bit grey (a copy: the message's buffer is not kept). Fails naming the
/// encoding when it is not mono8, rgb8 or bgr8, or the size when the data does not fill it.
Result<cv::Mat> grey_image(const msgs::ImageMessage& image);
/// The image as 8-bit BGR (rgb8, bgr8) or grey (mono8), a copy; fails as grey_image().
Result<cv::Mat> colour_image(const msgs::ImageMessage& image);

}  // namespace hanzo::fusion::vision
