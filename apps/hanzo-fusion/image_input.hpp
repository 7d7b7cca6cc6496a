#pragma once
// Image files given on the command line, read for the vision and privacy commands.

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::app {

/// cv::imread(path, imread_flags) of a file that exists and holds the whole image (a truncated
/// PNG / JPEG is refused with what is missing, before a decoder prints its own lines); one-line
/// errors naming the file.
Result<cv::Mat> read_image_input(const std::string& path, int imread_flags);

/// The image files named by `inputs` (files as given, folders searched recursively, sorted),
/// every `step`-th of each folder. Fails naming a missing input or a folder without images.
Result<std::vector<std::string>> collect_images(const std::vector<std::string>& inputs, int step);

}  // namespace hanzo::fusion::app
