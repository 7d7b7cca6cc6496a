#include "hanzo/fusion/vision/image_message.hpp"

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::vision {
namespace {

// The message's pixels without a copy (mono8: CV_8UC1; rgb8 / bgr8: CV_8UC3 as stored).
Result<cv::Mat> wrap(const msgs::ImageMessage& image) {
  const int rows = static_cast<int>(image.height), columns = static_cast<int>(image.width);
  if (image.data.size() != static_cast<std::size_t>(rows) * static_cast<std::size_t>(columns) * msgs::bytes_per_pixel(image.encoding)) {
    return Error(fmt::format("image data is {} bytes, {} x {} {} needs {}", image.data.size(), columns, rows, msgs::to_string(image.encoding),
                             static_cast<std::size_t>(rows) * static_cast<std::size_t>(columns) * msgs::bytes_per_pixel(image.encoding)));
  }
  auto* data = const_cast<uint8_t*>(image.data.data());
  switch (image.encoding) {
    case msgs::ImageEncoding::kMono8: return cv::Mat(rows, columns, CV_8UC1, data);
    case msgs::ImageEncoding::kRgb8:
    case msgs::ImageEncoding::kBgr8: return cv::Mat(rows, columns, CV_8UC3, data);
    default: return Error(fmt::format("image encoding {} is not mono8, rgb8 or bgr8", msgs::to_string(image.encoding)));
  }
}

}  // namespace

Result<cv::Mat> grey_image(const msgs::ImageMessage& image) {
  cv::Mat pixels;
  HANZO_ASSIGN_OR_RETURN(pixels, wrap(image));
  if (image.encoding == msgs::ImageEncoding::kMono8) return pixels.clone();
  cv::Mat grey;
  cv::cvtColor(pixels, grey, image.encoding == msgs::ImageEncoding::kRgb8 ? cv::COLOR_RGB2GRAY : cv::COLOR_BGR2GRAY);
  return grey;
}

Result<cv::Mat> colour_image(const msgs::ImageMessage& image) {
  cv::Mat pixels;
  HANZO_ASSIGN_OR_RETURN(pixels, wrap(image));
  if (image.encoding == msgs::ImageEncoding::kMono8) return pixels.clone();
  cv::Mat bgr;
  if (image.encoding == msgs::ImageEncoding::kRgb8) {
    cv::cvtColor(pixels, bgr, cv::COLOR_RGB2BGR);
  } else {
    bgr = pixels.clone();
  }
  return bgr;
}

}  // namespace hanzo::fusion::vision
