#include "image_files.hpp"

#include "hanzo/fusion/io/image_file_check.hpp"

#include <cmath>
#include <filesystem>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::io {

Result<msgs::ImageMessage> read_image_file(const std::string& path, Timestamp timestamp, const std::string& frame_id,
                                           double depth_to_millimeters) {
  if (!std::filesystem::is_regular_file(path)) return Error(fmt::format("{}: no such image file", path));
  HANZO_RETURN_IF_ERROR(check_image_file_complete(path));
  cv::Mat image;
  try {
    image = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    return Error(fmt::format("{}: cannot decode image ({})", path, e.what()));
  }
  if (image.empty()) return Error(fmt::format("{}: cannot decode image (unsupported or corrupt file)", path));
  msgs::ImageMessage message;
  message.timestamp = timestamp;
  message.frame_id = frame_id;
  message.width = static_cast<uint32_t>(image.cols);
  message.height = static_cast<uint32_t>(image.rows);
  cv::Mat packed;
  switch (image.type()) {
    case CV_8UC1:
      message.encoding = msgs::ImageEncoding::kMono8;
      packed = image;
      break;
    case CV_8UC3:
      message.encoding = msgs::ImageEncoding::kRgb8;
      cv::cvtColor(image, packed, cv::COLOR_BGR2RGB);
      break;
    case CV_8UC4:
      message.encoding = msgs::ImageEncoding::kRgb8;
      cv::cvtColor(image, packed, cv::COLOR_BGRA2RGB);
      break;
    case CV_16UC1:
      message.encoding = msgs::ImageEncoding::kDepth16;
      if (depth_to_millimeters == 1.0) {
        packed = image;
      } else {
        image.convertTo(packed, CV_16UC1, depth_to_millimeters);  // saturating, rounds to nearest
      }
      break;
    default:
      return Error(fmt::format("{}: unsupported image layout ({} channels of depth {}; expected 8-bit gray/colour or 16-bit depth)",
                               path, image.channels(), image.depth()));
  }
  if (!packed.isContinuous()) packed = packed.clone();
  const auto* begin = packed.ptr<uint8_t>();
  message.data.assign(begin, begin + packed.total() * packed.elemSize());
  return message;
}

}  // namespace hanzo::fusion::io
