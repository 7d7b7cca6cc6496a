#pragma once
// FeatureExtractor: what a matcher needs of a keypoint detector and descriptor, so that ORB
// (OrbExtractor) and learned extractors (ai::LearnedFeatureExtractor, the optional AI module)
// are interchangeable in `features match`, image-pair matching and the visual frontends.
//
// ImageFeatures::descriptors is one row per keypoint: CV_8UC1 with 32 bytes a row (ORB, matched
// by Hamming distance) or CV_32FC1 of unit-length rows (learned, matched by Euclidean distance).
// Keypoints are in pixels of the given image (u right, v down, origin at the centre of the
// top-left pixel); cv::KeyPoint::response is the detector's score.

#include <string>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/vision/orb_extractor.hpp"

namespace hanzo::fusion::vision {

class FeatureExtractor {
 public:
  virtual ~FeatureExtractor() = default;
  /// Features of an 8-bit grey, BGR or BGRA image; keypoints only where `mask` (CV_8UC1 of the
  /// image's size, optional) is non-zero. Thread-safe.
  virtual Result<ImageFeatures> extract(const cv::Mat& image, const cv::Mat& mask = cv::Mat()) const = 0;
  /// "orb", "aliked-t16", ...
  virtual std::string name() const = 0;
  /// The descriptors' type: CV_8UC1 (binary) or CV_32FC1 (float).
  virtual int descriptor_type() const = 0;
};

/// OrbExtractor behind the FeatureExtractor interface.
class OrbFeatureExtractor final : public FeatureExtractor {
 public:
  explicit OrbFeatureExtractor(OrbExtractorConfig config = {}) : orb_(std::move(config)) {}
  Result<ImageFeatures> extract(const cv::Mat& image, const cv::Mat& mask = cv::Mat()) const override { return orb_.extract(image, mask); }
  std::string name() const override { return "orb"; }
  int descriptor_type() const override { return CV_8UC1; }
  const OrbExtractorConfig& config() const { return orb_.config(); }

 private:
  OrbExtractor orb_;
};

}  // namespace hanzo::fusion::vision
