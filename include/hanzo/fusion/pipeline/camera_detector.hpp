#pragma once
// CameraDetector: the object detector of fusion.vision.detector (config::DetectorSelection) on
// camera images: the AI module's NanoDet (ai/object_detector.hpp, built with HANZO_FUSION_AI).
// The one place the pipeline and the command line turn that selection into a detector.
//
// Failure (make): type none, a build without the AI module (the error names the CMake option and
// the package), a model that cannot be found or read (the error names the path or the folders
// looked in). detect(): an image of an encoding other than mono8 / rgb8 / bgr8 or whose data does
// not fill it. `field` (the configuration key or command-line option) prefixes every error.

#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::pipeline {

/// Whether this build has the object detector.
bool object_detector_available();

class CameraDetector {
 public:
  static Result<std::unique_ptr<CameraDetector>> make(const config::DetectorSelection& selection, const std::string& field);
  ~CameraDetector();
  CameraDetector(const CameraDetector&) = delete;
  CameraDetector& operator=(const CameraDetector&) = delete;

  /// The objects in an 8-bit grey / BGR image, best score first (pixels of that image).
  Result<std::vector<msgs::Detection2D>> detect(const cv::Mat& image) const;
  /// The image's detections as its vision pipeline would send them: its timestamp, frame and size.
  Result<msgs::DetectionsMessage> detect(const msgs::ImageMessage& image) const;
  /// The model file in use.
  const std::string& model_path() const;

  struct Model;

 private:
  explicit CameraDetector(std::unique_ptr<Model> model);
  std::unique_ptr<Model> model_;
};

}  // namespace hanzo::fusion::pipeline
