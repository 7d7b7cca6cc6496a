#pragma once
// ImageQualityMonitor: says whether a camera image is fit for feature tracking, and if not why:
// too dark, washed out by glare, or blurred by motion. The visual-inertial odometry reports
// these conditions with the frames it loses, so that an operator sees why vision dropped out
// while the IMU carried the estimate.
//
// Measures (grey image, 8 bit):
//   mean_intensity      mean grey level, 0-255
//   saturated_fraction  share of pixels at or above saturation_level
//   sharpness           mean absolute Laplacian (3 x 3) of the image at half resolution over
//                       the same at an eighth: blur takes the fine detail and leaves the
//                       coarse, while a darker or plainer scene lowers both (so the ratio
//                       depends little on brightness and texture)
// Conditions, checked in this order:
//   dark         mean_intensity < dark_mean_intensity
//   glare        saturated_fraction > glare_saturated_fraction
//   motion_blur  sharpness < blur_sharpness_ratio x the median sharpness of the camera's last
//                sharpness_history frames that were neither dark nor glare (only a sudden drop
//                against its own recent frames is blur; a lasting change, a new scene, becomes
//                the norm once it fills half the history); needs min_history_for_blur frames
//   good         otherwise
// Failure cases: an empty image or one that is not 8-bit single channel is refused.

#include <deque>
#include <string_view>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::vision {

enum class ImageCondition { kGood, kDark, kGlare, kMotionBlur };
/// "good", "dark", "glare", "motion_blur".
std::string_view to_string(ImageCondition condition);

struct ImageQualityConfig {
  /// Mean grey level under which an image is dark (a tenth of the range: what auto-exposure
  /// cannot lift any more).
  double dark_mean_intensity = 25.0;
  /// Grey level counted as saturated, and the share of such pixels that makes glare.
  int saturation_level = 250;
  double glare_saturated_fraction = 0.15;
  /// Sharpness below this fraction of the recent median is motion blur.
  double blur_sharpness_ratio = 0.65;
  int sharpness_history = 30;       ///< frames in the running median (2-3 s of a 10-15 Hz camera)
  int min_history_for_blur = 5;     ///< frames seen before blur is judged
};

/// Checks every field; the error names the first field out of range.
Status validate(const ImageQualityConfig& config);

struct ImageQuality {
  double mean_intensity = 0.0;
  double saturated_fraction = 0.0;
  double sharpness = 0.0;
  ImageCondition condition = ImageCondition::kGood;
};

class ImageQualityMonitor {
 public:
  /// Fails when the configuration is out of range.
  static Result<ImageQualityMonitor> create(const ImageQualityConfig& config = {});

  /// Measures the image and judges it against this camera's recent good frames (header
  /// comment). Fails, changing nothing, for an empty or non-mono8 image.
  Result<ImageQuality> assess(const cv::Mat& grey);

 private:
  explicit ImageQualityMonitor(const ImageQualityConfig& config) : config_(config) {}
  ImageQualityConfig config_;
  std::deque<double> recent_sharpness_;
};

}  // namespace hanzo::fusion::vision
