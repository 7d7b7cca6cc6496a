#pragma once
// Image files of the dataset importers (PNG, JPEG, ... through OpenCV's imgcodecs) as
// ImageMessages. Internal to the io module.
//
//   8-bit, 1 channel   -> mono8
//   8-bit, 3 channels  -> rgb8 (OpenCV's BGR order swapped)
//   8-bit, 4 channels  -> rgb8 (alpha dropped)
//   16-bit, 1 channel  -> depth16 in millimetres: value * depth_to_millimeters, rounded
//                         (TUM RGB-D stores 5000 per metre: 0.2); 0 stays 0 (no measurement)
// Anything else is an error naming the file and what it holds.

#include <string>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::io {

Result<msgs::ImageMessage> read_image_file(const std::string& path, Timestamp timestamp, const std::string& frame_id,
                                           double depth_to_millimeters = 1.0);

}  // namespace hanzo::fusion::io
