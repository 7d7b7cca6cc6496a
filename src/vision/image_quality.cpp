#include "hanzo/fusion/vision/image_quality.hpp"

#include <algorithm>
#include <vector>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::vision {

std::string_view to_string(ImageCondition condition) {
  switch (condition) {
    case ImageCondition::kGood: return "good";
    case ImageCondition::kDark: return "dark";
    case ImageCondition::kGlare: return "glare";
    case ImageCondition::kMotionBlur: return "motion_blur";
  }
  return "invalid";
}

Status validate(const ImageQualityConfig& config) {
  if (!(config.dark_mean_intensity >= 0.0 && config.dark_mean_intensity < 255.0)) {
    return Error("ImageQualityConfig.dark_mean_intensity: must be in [0, 255)", "dark_mean_intensity");
  }
  if (config.saturation_level < 1 || config.saturation_level > 255) return Error("ImageQualityConfig.saturation_level: must be in 1..255", "saturation_level");
  if (!(config.glare_saturated_fraction > 0.0 && config.glare_saturated_fraction <= 1.0)) {
    return Error("ImageQualityConfig.glare_saturated_fraction: must be in (0, 1]", "glare_saturated_fraction");
  }
  if (!(config.blur_sharpness_ratio >= 0.0 && config.blur_sharpness_ratio < 1.0)) {
    return Error("ImageQualityConfig.blur_sharpness_ratio: must be in [0, 1)", "blur_sharpness_ratio");
  }
  if (config.sharpness_history < 1) return Error("ImageQualityConfig.sharpness_history: must be at least 1", "sharpness_history");
  if (config.min_history_for_blur < 1 || config.min_history_for_blur > config.sharpness_history) {
    return Error("ImageQualityConfig.min_history_for_blur: must be in 1..sharpness_history", "min_history_for_blur");
  }
  return ok_status();
}

Result<ImageQualityMonitor> ImageQualityMonitor::create(const ImageQualityConfig& config) {
  HANZO_RETURN_IF_ERROR(validate(config));
  return ImageQualityMonitor(config);
}

Result<ImageQuality> ImageQualityMonitor::assess(const cv::Mat& grey) {
  if (grey.empty() || grey.type() != CV_8UC1) return Error(fmt::format("image quality: a non-empty mono8 image is needed (type {})", grey.type()));
  ImageQuality quality;
  quality.mean_intensity = cv::mean(grey)[0];
  quality.saturated_fraction = static_cast<double>(cv::countNonZero(grey >= config_.saturation_level)) / static_cast<double>(grey.total());
  cv::Mat half, eighth, laplacian;
  cv::pyrDown(grey, half);
  cv::pyrDown(half, eighth);
  cv::pyrDown(eighth, eighth);
  cv::Laplacian(half, laplacian, CV_16S, 3);
  const double fine = cv::mean(cv::abs(laplacian))[0];
  cv::Laplacian(eighth, laplacian, CV_16S, 3);
  const double coarse = cv::mean(cv::abs(laplacian))[0];
  quality.sharpness = fine / std::max(coarse, 1e-3);

  if (quality.mean_intensity < config_.dark_mean_intensity) {
    quality.condition = ImageCondition::kDark;
  } else if (quality.saturated_fraction > config_.glare_saturated_fraction) {
    quality.condition = ImageCondition::kGlare;
  } else if (static_cast<int>(recent_sharpness_.size()) >= config_.min_history_for_blur) {
    std::vector<double> recent(recent_sharpness_.begin(), recent_sharpness_.end());
    std::nth_element(recent.begin(), recent.begin() + static_cast<std::ptrdiff_t>(recent.size() / 2), recent.end());
    if (quality.sharpness < config_.blur_sharpness_ratio * recent[recent.size() / 2]) quality.condition = ImageCondition::kMotionBlur;
  }
  if (quality.condition == ImageCondition::kGood || quality.condition == ImageCondition::kMotionBlur) {
    recent_sharpness_.push_back(quality.sharpness);
    if (static_cast<int>(recent_sharpness_.size()) > config_.sharpness_history) recent_sharpness_.pop_front();
  }
  return quality;
}

}  // namespace hanzo::fusion::vision
