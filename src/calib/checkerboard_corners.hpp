#pragma once
// Checkerboard corners in images (internal to the calib module): what the camera, stereo and
// camera-LiDAR calibrations share.

#include <cstddef>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/calib/camera_calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::calib {

/// The image as 8-bit grey (no copy for mono8); an error naming images[index] for a depth
/// encoding or a data size that does not match width x height.
Result<cv::Mat> grey_of(const msgs::ImageMessage& image, std::size_t index);

/// The board's inner corners in its own frame (m): row by row from the first corner, z = 0.
std::vector<cv::Point3f> board_points(const CheckerboardTarget& target);

/// Finds every inner corner of the board (OpenCV findChessboardCorners, refined to sub-pixel by
/// cornerSubPix) in OpenCV's order; false when the whole board was not found.
bool find_checkerboard_corners(const cv::Mat& grey, const CheckerboardTarget& target, std::vector<cv::Point2f>* corners);

}  // namespace hanzo::fusion::calib
