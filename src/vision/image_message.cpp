#include "hanzo/fusion/vision/image_message.hpp"

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::vision {

Result<cv::Mat> grey_image(const msgs::ImageMessage& image) {
  const int rows = static_cast<int>(image.height), columns = static_cast<int>(image.width);
  if (image.data.size() != static_cast<std::size_t>(rows) * static_cast<std::size_t>(columns) * msgs::bytes_per_pixel(image.encoding)) {
    return Error(fmt::format("image data is {} bytes, {} x {} {} needs {}", image.data.size(), columns, rows, msgs::to_string(image.encoding),
                             static_cast<std::size_t>(rows) * static_cast<std::size_t>(columns) * msgs::bytes_per_pixel(image.encoding)));
  }
  auto* data = const_cast<uint8_t*>(image.data.data());
  switch (image.encoding) {
    case msgs::ImageEncoding::kMono8: return cv::Mat(rows, columns, CV_8UC1, data).clone();
    case msgs::ImageEncoding::kRgb8:
    case msgs::ImageEncoding::kBgr8: {
      cv::Mat grey;
      cv::cvtColor(cv::Mat(rows, columns, CV_8UC3, data), grey, image.encoding == msgs::ImageEncoding::kRgb8 ? cv::COLOR_RGB2GRAY : cv::COLOR_BGR2GRAY);
      return grey;
    }
    default: return Error(fmt::format("image encoding {} is not mono8, rgb8 or bgr8", msgs::to_string(image.encoding)));
  }
}

}  // namespace hanzo::fusion::vision
