#pragma once
// The feature benchmarks' frame: the first image of ../shared/data/euroc_v101_micro's left camera,
// its central 640 x 480 pixels, grey.

#include <filesystem>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

namespace hanzo::fusion::bench {

inline cv::Mat euroc_frame() {
  const std::string folder = std::string(HANZO_DATA_DIR) + "/euroc_v101_micro/mav0/cam0/data";
  std::string first;
  for (const auto& entry : std::filesystem::directory_iterator(folder)) {
    if (first.empty() || entry.path().string() < first) first = entry.path().string();
  }
  const cv::Mat image = cv::imread(first, cv::IMREAD_GRAYSCALE);
  return image(cv::Rect((image.cols - 640) / 2, 0, 640, 480)).clone();
}

}  // namespace hanzo::fusion::bench
