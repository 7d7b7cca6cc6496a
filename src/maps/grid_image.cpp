#include "grid_image.hpp"

#include <vector>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/core/yaml_value.hpp"

namespace hanzo::fusion::maps {

cv::Mat grid_image(const msgs::OccupancyGridLayer& flat, const std::function<uint8_t(float)>& pixel_of) {
  cv::Mat image(static_cast<int>(flat.size_y), static_cast<int>(flat.size_x), CV_8UC1);
  for (uint32_t y = 0; y < flat.size_y; ++y) {
    uint8_t* row = image.ptr<uint8_t>(static_cast<int>(flat.size_y - 1 - y));
    for (uint32_t x = 0; x < flat.size_x; ++x) row[x] = pixel_of(flat.occupancy[std::size_t{y} * flat.size_x + x]);
  }
  return image;
}

Status write_image(const std::string& path, const cv::Mat& image, const std::string& extension) {
  std::vector<uchar> bytes;
  try {
    if (!cv::imencode(extension, image, bytes)) return Error{fmt::format("{}: cannot encode the image", path)};
  } catch (const cv::Exception& error) {
    return Error{fmt::format("{}: cannot encode the image ({})", path, error.what())};
  }
  return yaml::write_file_atomically(path, std::string(bytes.begin(), bytes.end()));
}

}  // namespace hanzo::fusion::maps
