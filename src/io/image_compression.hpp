#pragma once
// Images stored compressed in sensor logs (v1::ImageMessage::compression): PNG (lossless) or
// JPEG (lossy, smaller) files in `data`, decoded back to the raw layout of `encoding` when read.

#include <string_view>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/v1/sensors.pb.h"

namespace hanzo::fusion::io {

/// The image as a v1::ImageMessage with its pixels as a PNG or JPEG file (`compression` set).
/// Encodings the format cannot hold stay raw (compression ""): JPEG holds rgb8, bgr8 and
/// mono8; PNG also depth16; depth32f is always raw. jpeg_quality in [1, 100].
v1::ImageMessage compressed_image(const msgs::ImageMessage& image, ImageCompression compression, int jpeg_quality);

/// Replaces a compressed image's data by its raw pixels (compression cleared); an image without
/// compression is left as it is. Fails naming what is wrong: an unknown compression, a file
/// that does not decode, or one whose size or channels differ from width, height and encoding.
Status decompress_image(v1::ImageMessage& image);

}  // namespace hanzo::fusion::io
