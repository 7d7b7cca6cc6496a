#pragma once
// StaticMask: where in an image the visual frontends may take features. A type of its own so
// that a mask is never passed where a second image (stereo right, depth) is meant.

#include <opencv2/core.hpp>

namespace hanzo::fusion::vision {

struct StaticMask {
  /// CV_8UC1 of the image's size: non-zero on the static scene, zero on moving objects (a
  /// detector's people and vehicles). Empty: the whole image is usable.
  cv::Mat pixels;

  bool empty() const { return pixels.empty(); }
};

}  // namespace hanzo::fusion::vision
