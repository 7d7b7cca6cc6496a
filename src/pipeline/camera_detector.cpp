#include "hanzo/fusion/pipeline/camera_detector.hpp"

#include <fmt/format.h>

#include "hanzo/fusion/vision/image_message.hpp"

#ifdef HANZO_FUSION_WITH_AI
#include "hanzo/fusion/ai/object_detector.hpp"
#endif

namespace hanzo::fusion::pipeline {

bool object_detector_available() {
#ifdef HANZO_FUSION_WITH_AI
  return true;
#else
  return false;
#endif
}

#ifdef HANZO_FUSION_WITH_AI
struct CameraDetector::Model {
  std::unique_ptr<ai::ObjectDetector> detector;
};
#else
struct CameraDetector::Model {
  std::string none;
};
#endif

CameraDetector::CameraDetector(std::unique_ptr<Model> model) : model_(std::move(model)) {}
CameraDetector::~CameraDetector() = default;

Result<std::unique_ptr<CameraDetector>> CameraDetector::make(const config::DetectorSelection& selection, const std::string& field) {
  if (!selection.enabled()) return Error(fmt::format("{}: type none: no detector to run", field), field);
#ifdef HANZO_FUSION_WITH_AI
  ai::ObjectDetectorConfig config;
  config.model_path = selection.model;
  config.score_threshold = static_cast<float>(selection.score_threshold);
  Result<std::unique_ptr<ai::ObjectDetector>> detector = ai::ObjectDetector::load(config);
  if (!detector) return Error(fmt::format("{}: {}", field, detector.error().message), field);
  auto model = std::make_unique<Model>();
  model->detector = std::move(detector).value();
  return std::unique_ptr<CameraDetector>(new CameraDetector(std::move(model)));
#else
  return Error(fmt::format("{}: {}: this build has no object detector (built without HANZO_FUSION_AI; install libtorch-dev)", field, selection.type),
               field);
#endif
}

Result<std::vector<msgs::Detection2D>> CameraDetector::detect(const cv::Mat& image) const {
#ifdef HANZO_FUSION_WITH_AI
  return model_->detector->detect(image);
#else
  (void)image;
  return Error("this build has no object detector");
#endif
}

Result<msgs::DetectionsMessage> CameraDetector::detect(const msgs::ImageMessage& image) const {
  cv::Mat pixels;
  HANZO_ASSIGN_OR_RETURN(pixels, vision::colour_image(image));
  msgs::DetectionsMessage detections;
  detections.timestamp = image.timestamp;
  detections.frame_id = image.frame_id;
  detections.image_width = image.width;
  detections.image_height = image.height;
  HANZO_ASSIGN_OR_RETURN(detections.detections, detect(pixels));
  return detections;
}

const std::string& CameraDetector::model_path() const {
#ifdef HANZO_FUSION_WITH_AI
  return model_->detector->model_path();
#else
  return model_->none;
#endif
}

}  // namespace hanzo::fusion::pipeline
