#include "checkerboard_corners.hpp"

#include <fmt/format.h>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::calib {

Result<cv::Mat> grey_of(const msgs::ImageMessage& image, std::size_t index) {
  const bool three_channels = image.encoding == msgs::ImageEncoding::kRgb8 || image.encoding == msgs::ImageEncoding::kBgr8;
  if (three_channels || image.encoding == msgs::ImageEncoding::kMono8) {
    const std::size_t needed = std::size_t{image.width} * image.height * (three_channels ? 3U : 1U);
    if (image.data.size() != needed) {
      return Error(fmt::format("images[{}]: {} bytes, but {} x {} px {} takes {}", index, image.data.size(), image.width, image.height,
                               msgs::to_string(image.encoding), needed),
                   fmt::format("images[{}]", index));
    }
  }
  cv::Mat data(static_cast<int>(image.height), static_cast<int>(image.width), CV_8UC1, const_cast<uint8_t*>(image.data.data()));
  switch (image.encoding) {
    case msgs::ImageEncoding::kMono8: return data;
    case msgs::ImageEncoding::kRgb8:
    case msgs::ImageEncoding::kBgr8: {
      const cv::Mat color(static_cast<int>(image.height), static_cast<int>(image.width), CV_8UC3, const_cast<uint8_t*>(image.data.data()));
      cv::Mat grey;
      cv::cvtColor(color, grey, image.encoding == msgs::ImageEncoding::kRgb8 ? cv::COLOR_RGB2GRAY : cv::COLOR_BGR2GRAY);
      return grey;
    }
    default:
      return Error(fmt::format("images[{}]: encoding {} is not an intensity image (mono8, rgb8 or bgr8)", index,
                               msgs::to_string(image.encoding)),
                   fmt::format("images[{}]", index));
  }
}

std::vector<cv::Point3f> board_points(const CheckerboardTarget& target) {
  std::vector<cv::Point3f> points;
  for (int y = 0; y < target.inner_corners_y; ++y) {
    for (int x = 0; x < target.inner_corners_x; ++x) {
      points.emplace_back(static_cast<float>(x * target.square_size), static_cast<float>(y * target.square_size), 0.0F);
    }
  }
  return points;
}

bool find_checkerboard_corners(const cv::Mat& grey, const CheckerboardTarget& target, std::vector<cv::Point2f>* corners) {
  const cv::Size pattern(target.inner_corners_x, target.inner_corners_y);
  if (!cv::findChessboardCorners(grey, pattern, *corners, cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK)) {
    return false;
  }
  cv::cornerSubPix(grey, *corners, cv::Size(5, 5), cv::Size(-1, -1), cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 50, 1e-3));
  return true;
}

}  // namespace hanzo::fusion::calib
