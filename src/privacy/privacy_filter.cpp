#include "hanzo/fusion/privacy/privacy_filter.hpp"

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <optional>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>
#include <opencv2/objdetect.hpp>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "yunet_face_detector.hpp"

namespace hanzo::fusion::privacy {
namespace {

constexpr const char* kFaceModel = "face_detection_yunet.onnx";
constexpr const char* kPlateCascade = "/usr/share/opencv4/haarcascades/haarcascade_russian_plate_number.xml";
constexpr const char* kFaceCascade = "/usr/share/opencv4/haarcascades/haarcascade_frontalface_default.xml";

// A cascade file loaded, or an error naming it and its package.
Status load_cascade(cv::CascadeClassifier& cascade, const std::string& path, const char* what) {
  if (!std::filesystem::is_regular_file(path) || !cascade.load(path)) {
    return Error(fmt::format("{} cascade '{}' cannot be loaded (Debian package opencv-data)", what, path));
  }
  return ok_status();
}

cv::Rect enlarged(const cv::Rect& box, double margin, const cv::Size& size) {
  const int dx = static_cast<int>(std::lround(margin * box.width)), dy = static_cast<int>(std::lround(margin * box.height));
  return cv::Rect(box.x - dx, box.y - dy, box.width + 2 * dx, box.height + 2 * dy) & cv::Rect(cv::Point(0, 0), size);
}

}  // namespace

std::string_view to_string(Redaction redaction) { return redaction == Redaction::kBlur ? "blur" : "black"; }

Result<Redaction> parse_redaction(std::string_view name) {
  if (name == "blur") return Redaction::kBlur;
  if (name == "black") return Redaction::kBlackOut;
  return Error(fmt::format("unknown redaction '{}' (expected blur or black)", name));
}

Result<std::string> find_face_model() { return find_model_file(kFaceModel, HANZO_INSTALLED_MODELS_DIR, HANZO_SOURCE_MODELS_DIR); }
std::string default_plate_cascade_path() { return kPlateCascade; }
std::string default_face_cascade_path() { return kFaceCascade; }

struct PrivacyFilter::Models {
  std::optional<YunetFaceDetector> faces;
  std::optional<cv::CascadeClassifier> face_cascade;  // the fallback without YuNet's file
  cv::CascadeClassifier plates;
};

std::string_view PrivacyFilter::face_detector() const {
  if (models_->faces) return "yunet";
  if (models_->face_cascade) return "haar_cascade";
  return "none";
}

PrivacyFilter::PrivacyFilter(PrivacyFilterConfig config, std::unique_ptr<Models> models)
    : config_(std::move(config)), models_(std::move(models)) {}
PrivacyFilter::~PrivacyFilter() = default;

Result<std::unique_ptr<PrivacyFilter>> PrivacyFilter::create(const PrivacyFilterConfig& config) {
  if (!(config.face_score_threshold >= 0.0 && config.face_score_threshold <= 1.0)) {
    return Error(fmt::format("face score threshold must be in [0, 1], got {}", config.face_score_threshold));
  }
  if (!(config.margin >= 0.0 && config.margin <= 1.0)) return Error(fmt::format("margin must be in [0, 1], got {}", config.margin));
  if (config.min_plate_width < 8) return Error(fmt::format("smallest plate width must be >= 8 px, got {}", config.min_plate_width));
  auto models = std::make_unique<Models>();
  if (config.faces) {
    const Result<std::string> found = config.face_model_path.empty() ? find_face_model() : Result<std::string>(config.face_model_path);
    if (found) {
      Result<YunetFaceDetector> detector = YunetFaceDetector::load(*found);
      if (!detector) return detector.error();
      models->faces.emplace(std::move(detector).value());
    } else {
      models->face_cascade.emplace();
      HANZO_RETURN_IF_ERROR(load_cascade(*models->face_cascade, kFaceCascade, "face"));
      logger()->warn("privacy filter: {}: faces are searched with OpenCV's Haar cascade instead of YuNet, with lower recall and "
                     "more false faces (docs/security.md); put {} in ${}",
                     found.error().message, kFaceModel, kModelsEnvironment);
    }
  }
  if (config.licence_plates) {
    HANZO_RETURN_IF_ERROR(load_cascade(models->plates, config.plate_cascade_path.empty() ? default_plate_cascade_path() : config.plate_cascade_path,
                                       "licence plate"));
  }
  return std::unique_ptr<PrivacyFilter>(new PrivacyFilter(config, std::move(models)));
}

Result<std::vector<RedactedRegion>> PrivacyFilter::detect(const cv::Mat& image) {
  if (image.empty()) return Error("the image is empty");
  if (image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3)) {
    return Error(fmt::format("expected an 8-bit grey or BGR image, got {} channel(s) of depth {}", image.channels(), image.depth()));
  }
  cv::Mat bgr, grey;
  if (image.channels() == 1) {
    grey = image;
    cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
  } else {
    bgr = image;
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  }
  std::vector<RedactedRegion> regions;
  try {
    if (models_->faces) {
      for (const FaceDetection& face : models_->faces->detect(bgr, config_.face_score_threshold)) regions.push_back({"face", face.box, face.score});
    } else if (models_->face_cascade) {
      std::vector<cv::Rect> faces;
      models_->face_cascade->detectMultiScale(grey, faces, 1.1, 3, 0, cv::Size(24, 24));  // as bench_privacy's peer
      for (const cv::Rect& face : faces) regions.push_back({"face", face, 1.0});
    }
    if (config_.licence_plates) {
      std::vector<cv::Rect> plates;
      models_->plates.detectMultiScale(grey, plates, 1.1, 3, 0, cv::Size(config_.min_plate_width, config_.min_plate_width / 4));
      for (const cv::Rect& plate : plates) regions.push_back({"licence_plate", plate, 1.0});
    }
  } catch (const cv::Exception& error) {
    return Error(fmt::format("privacy filter: {}", error.msg));
  }
  return regions;
}

void PrivacyFilter::redact(cv::Mat& image, const std::vector<RedactedRegion>& regions) const {
  for (const RedactedRegion& region : regions) {
    const cv::Rect area = enlarged(region.box, config_.margin, image.size());
    if (area.area() == 0) continue;
    cv::Mat pixels = image(area);
    if (config_.redaction == Redaction::kBlackOut) {
      pixels.setTo(cv::Scalar::all(0));
    } else {
      const double sigma = std::max(2.0, 0.25 * std::max(area.width, area.height));
      cv::Mat blurred;
      cv::GaussianBlur(pixels, blurred, cv::Size(), sigma, sigma, cv::BORDER_REPLICATE);
      blurred.copyTo(pixels);
    }
  }
  if (!regions.empty()) logger()->debug("privacy filter: {} region(s) redacted ({})", regions.size(), to_string(config_.redaction));
}

Result<std::vector<RedactedRegion>> PrivacyFilter::apply(cv::Mat& image) {
  Result<std::vector<RedactedRegion>> regions = detect(image);
  if (regions) redact(image, *regions);
  return regions;
}

Result<std::vector<RedactedRegion>> PrivacyFilter::apply(msgs::ImageMessage& message) {
  int type = 0;
  switch (message.encoding) {
    case msgs::ImageEncoding::kRgb8:
    case msgs::ImageEncoding::kBgr8: type = CV_8UC3; break;
    case msgs::ImageEncoding::kMono8: type = CV_8UC1; break;
    case msgs::ImageEncoding::kDepth16:
    case msgs::ImageEncoding::kDepth32f: return std::vector<RedactedRegion>{};
  }
  const std::size_t expected = static_cast<std::size_t>(message.width) * message.height * msgs::bytes_per_pixel(message.encoding);
  if (message.width == 0 || message.height == 0 || message.data.size() != expected) {
    return Error(fmt::format("image {} x {} {}: {} bytes of data, expected {}", message.width, message.height, msgs::to_string(message.encoding),
                             message.data.size(), expected));
  }
  cv::Mat pixels(static_cast<int>(message.height), static_cast<int>(message.width), type, message.data.data());
  // The detector reads BGR: rgb8 is converted into a buffer of its own (converting into a header
  // that shares the message's pixels would swap the message's channels in place).
  cv::Mat bgr;
  if (message.encoding == msgs::ImageEncoding::kRgb8) {
    cv::cvtColor(pixels, bgr, cv::COLOR_RGB2BGR);
  } else {
    bgr = pixels;
  }
  Result<std::vector<RedactedRegion>> regions = detect(bgr);
  if (regions) redact(pixels, *regions);  // the message's own buffer
  return regions;
}

}  // namespace hanzo::fusion::privacy
