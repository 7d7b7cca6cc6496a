#pragma once
// PrivacyFilter: finds faces and licence plates in camera images and blurs (or blacks out) them
// before anything is stored (spec, security: camera data from public spaces passes a privacy
// filter before storage).
//
// Faces: the YuNet detector (face_detection_yunet.onnx from OpenCV's model zoo, which the
// repository does not ship: the file given, or found by find_model_file() in
// $HANZO_FUSION_MODELS) run with cv::dnn on the image padded to a multiple of 32 pixels, its
// outputs decoded here (Debian's
// OpenCV 4.6 FaceDetectorYN expects the model's older output format). Per stride s in {8, 16, 32}
// and cell (row r, column c) of the (W/s) x (H/s) map:
//   score = sqrt(class * objectness),
//   centre = ((c + box_0) s, (r + box_1) s),  size = (exp(box_2) s, exp(box_3) s)
// followed by non-maximum suppression. Images larger than 640 pixels are searched again at
// 640 pixels on their longer side, so faces larger than the network's largest anchors are
// found too. Measured recall and false positives: docs/security.md.
//
// Without the YuNet file (and no path given), faces are found by OpenCV's Haar frontal-face
// cascade (Debian's opencv-data), with a warning: its recall is lower and it finds more false
// faces (docs/security.md); face_detector() says which one runs.
//
// Licence plates: OpenCV's Haar cascade for plates (Debian's opencv-data,
// haarcascade_russian_plate_number.xml), on the grey image.
//
// Each region is enlarged by `margin` of its size on every side and clipped to the image, then
// blurred with a Gaussian of sigma = size / 4 (a face becomes a smooth blob) or set to black.
// Grey (CV_8UC1) and colour (CV_8UC3, BGR) 8-bit images are accepted; anything else is refused.

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::privacy {

enum class Redaction { kBlur, kBlackOut };

/// "blur" / "black"; parse_redaction() refuses anything else with the allowed names.
std::string_view to_string(Redaction redaction);
Result<Redaction> parse_redaction(std::string_view name);

struct PrivacyFilterConfig {
  Redaction redaction = Redaction::kBlur;
  bool faces = true;
  bool licence_plates = true;
  /// YuNet ONNX file; "" = find_face_model(), else the Haar cascade fallback.
  std::string face_model_path;
  /// Face score threshold in [0, 1]: 0.7 finds every face of the test photos (down to 24 px)
  /// and none in 78 street images; 0.6 added a 19 x 24 px false face (docs/security.md).
  double face_score_threshold = 0.7;
  /// Plate cascade XML; "" = default_plate_cascade_path().
  std::string plate_cascade_path;
  /// Smallest plate searched, pixels wide.
  int min_plate_width = 24;
  /// Fraction of a region's size added on each side before redaction.
  double margin = 0.1;
};

struct RedactedRegion {
  std::string kind;  ///< "face" or "licence_plate"
  cv::Rect box;      ///< as detected (before the margin), pixels
  double score = 1.0;  ///< detector score in [0, 1] (1 for the plate cascade, which has none)
};

/// face_detection_yunet.onnx as find_model_file() finds it ($HANZO_FUSION_MODELS, the installed
/// share/hanzo-fusion/models, the source tree's models/); an error naming where it looked.
Result<std::string> find_face_model();
/// Debian's opencv-data cascades: licence plates, and the frontal faces of the fallback.
std::string default_plate_cascade_path();
std::string default_face_cascade_path();

class PrivacyFilter {
 public:
  /// Fails with a message naming the file when a model cannot be loaded.
  static Result<std::unique_ptr<PrivacyFilter>> create(const PrivacyFilterConfig& config);
  ~PrivacyFilter();
  PrivacyFilter(const PrivacyFilter&) = delete;
  PrivacyFilter& operator=(const PrivacyFilter&) = delete;

  /// The regions that apply() would redact, without changing the image.
  Result<std::vector<RedactedRegion>> detect(const cv::Mat& image);
  /// Detects and redacts in place; returns the regions. The image is unchanged on error.
  Result<std::vector<RedactedRegion>> apply(cv::Mat& image);
  /// Redacts the regions (enlarged by the margin) in any image of their size: 1, 3 or 4
  /// channels of 8 or 16 bits or float.
  void redact(cv::Mat& image, const std::vector<RedactedRegion>& regions) const;
  /// A camera message in place: rgb8, bgr8 and mono8 images are searched and redacted; depth
  /// images carry no faces and are left as they are (no regions).
  Result<std::vector<RedactedRegion>> apply(msgs::ImageMessage& image);

  const PrivacyFilterConfig& config() const { return config_; }
  /// "yunet", "haar_cascade" (YuNet's file was not found) or "none" (faces not searched).
  std::string_view face_detector() const;

 private:
  struct Models;
  PrivacyFilter(PrivacyFilterConfig config, std::unique_ptr<Models> models);

  PrivacyFilterConfig config_;
  std::unique_ptr<Models> models_;
};

}  // namespace hanzo::fusion::privacy
