#pragma once
// YuNet face detection with cv::dnn (the decoding is described in privacy_filter.hpp).

#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/dnn.hpp>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::privacy {

struct FaceDetection {
  cv::Rect box;  // pixels of the input image
  double score = 0.0;
};

class YunetFaceDetector {
 public:
  static Result<YunetFaceDetector> load(const std::string& model_path);
  /// Faces with score >= score_threshold in an 8-bit BGR image, after non-maximum suppression.
  std::vector<FaceDetection> detect(const cv::Mat& bgr, double score_threshold);

 private:
  explicit YunetFaceDetector(cv::dnn::Net net) : net_(std::move(net)) {}
  /// One pass at the image's own size (padded to a multiple of 32), boxes in its pixels.
  void detect_at_scale(const cv::Mat& bgr, double score_threshold, double scale, std::vector<cv::Rect2d>* boxes,
                       std::vector<float>* scores);

  cv::dnn::Net net_;
};

}  // namespace hanzo::fusion::privacy
