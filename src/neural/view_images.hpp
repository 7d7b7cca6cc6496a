#pragma once
// Helpers shared by the posed-image readers (transforms.json, sensor logs); private to the module.

#include <opencv2/core.hpp>

#include "hanzo/fusion/neural/view_dataset.hpp"

namespace hanzo::fusion::neural {

/// The 8-bit image (grey, BGR or BGRA as OpenCV reads it) as the view's RGB floats, downscaled
/// by config.downscale (area averaging); BGRA is composited on config.background and its alpha
/// kept as the mask.
Status to_view_image(const cv::Mat& read, const ViewDatasetConfig& config, PosedView& view);

/// scene_centre (the point nearest to every optical axis, else the cameras' mean position) and
/// camera_distance (the cameras' mean distance from it).
void set_scene_extent(ViewDataset& dataset);

}  // namespace hanzo::fusion::neural
