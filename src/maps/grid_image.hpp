#pragma once
// Images of 2D occupancy layers, shared by the exports and the diff picture: one pixel per
// cell, image row 0 = the grid's last y row (image up = world +y).

#include <cstdint>
#include <functional>
#include <string>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

/// One channel image of a layer with size_z == 1: pixel_of(probability) per cell.
cv::Mat grid_image(const msgs::OccupancyGridLayer& flat, const std::function<uint8_t(float)>& pixel_of);
/// Encodes (".png", ".pgm") and writes atomically.
Status write_image(const std::string& path, const cv::Mat& image, const std::string& extension);

}  // namespace hanzo::fusion::maps
