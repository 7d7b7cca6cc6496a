#include "image_input.hpp"

#include <algorithm>
#include <filesystem>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/io/image_file_check.hpp"

namespace hanzo::fusion::app {

Result<cv::Mat> read_image_input(const std::string& path, int imread_flags) {
  if (!std::filesystem::is_regular_file(path)) return Error(fmt::format("{}: no such file", path));
  HANZO_RETURN_IF_ERROR(io::check_image_file_complete(path));
  cv::Mat image;
  try {
    image = cv::imread(path, imread_flags);
  } catch (const cv::Exception& error) {
    return Error(fmt::format("{}: cannot decode the image ({})", path, error.msg));
  }
  if (image.empty()) return Error(fmt::format("{}: not an image OpenCV can read", path));
  return image;
}

Result<std::vector<std::string>> collect_images(const std::vector<std::string>& inputs, int step) {
  std::vector<std::string> images;
  for (const std::string& input : inputs) {
    std::error_code error;
    if (std::filesystem::is_directory(input, error)) {
      std::vector<std::string> found;
      for (const auto& entry : std::filesystem::recursive_directory_iterator(input, error)) {
        if (entry.is_regular_file() && io::has_image_extension(entry.path().string())) found.push_back(entry.path().string());
      }
      if (error) return Error(fmt::format("{}: cannot list the folder ({})", input, error.message()));
      std::sort(found.begin(), found.end());
      if (found.empty()) return Error(fmt::format("{}: no images (.png, .jpg, .pgm, .ppm, .bmp, .tif) in the folder", input));
      for (std::size_t i = 0; i < found.size(); i += static_cast<std::size_t>(step)) images.push_back(found[i]);
    } else if (std::filesystem::is_regular_file(input, error)) {
      images.push_back(input);
    } else {
      return Error(fmt::format("{}: no such file or folder", input));
    }
  }
  return images;
}


}  // namespace hanzo::fusion::app
