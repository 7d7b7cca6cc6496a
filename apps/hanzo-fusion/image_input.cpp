#include "image_input.hpp"

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

}  // namespace hanzo::fusion::app
