#include "yunet_face_detector.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>

#include <fmt/format.h>
#include <opencv2/core/utils/logger.hpp>
#include <opencv2/imgproc.hpp>

namespace hanzo::fusion::privacy {
namespace {

constexpr std::array<int, 3> kStrides{8, 16, 32};
constexpr int kCoarseSide = 640;       // second pass for faces larger than the largest anchors
constexpr float kNmsThreshold = 0.3F;  // intersection over union

}  // namespace

Result<YunetFaceDetector> YunetFaceDetector::load(const std::string& model_path) {
  if (!std::filesystem::is_regular_file(model_path)) {
    return Error(fmt::format("face model '{}' not found", model_path));
  }
  // OpenCV logs a bad file's parse errors over several lines of its own: silenced here, and its
  // exception's message put on one line.
  const cv::utils::logging::LogLevel level = cv::utils::logging::setLogLevel(cv::utils::logging::LOG_LEVEL_SILENT);
  Result<YunetFaceDetector> loaded = Error("");
  try {
    cv::dnn::Net net = cv::dnn::readNetFromONNX(model_path);
    loaded = net.empty() ? Result<YunetFaceDetector>(Error(fmt::format("face model '{}': not a network OpenCV can read", model_path)))
                         : Result<YunetFaceDetector>(YunetFaceDetector(std::move(net)));
  } catch (const cv::Exception& error) {
    std::string reason = error.msg;
    std::replace(reason.begin(), reason.end(), '\n', ' ');
    loaded = Error(fmt::format("face model '{}': not an ONNX network OpenCV can read ({})", model_path, reason));
  }
  cv::utils::logging::setLogLevel(level);
  return loaded;
}

void YunetFaceDetector::detect_at_scale(const cv::Mat& bgr, double score_threshold, double scale, std::vector<cv::Rect2d>* boxes,
                                        std::vector<float>* scores) {
  cv::Mat input = bgr;
  if (scale != 1.0) cv::resize(bgr, input, cv::Size(), scale, scale, cv::INTER_AREA);
  const int width = (input.cols + 31) / 32 * 32, height = (input.rows + 31) / 32 * 32;
  cv::Mat padded;
  cv::copyMakeBorder(input, padded, 0, height - input.rows, 0, width - input.cols, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  net_.setInput(cv::dnn::blobFromImage(padded));  // BGR, 0-255, no mean: as the model was trained
  std::vector<std::string> names;
  for (const int stride : kStrides) {
    for (const char* output : {"cls_", "obj_", "bbox_"}) names.push_back(output + std::to_string(stride));
  }
  std::vector<cv::Mat> outputs;
  net_.forward(outputs, names);
  for (std::size_t level = 0; level < kStrides.size(); ++level) {
    const int stride = kStrides[level];
    const int columns = width / stride, rows = height / stride;
    const cv::Mat& class_map = outputs[3 * level];
    const cv::Mat& object_map = outputs[3 * level + 1];
    const cv::Mat& box_map = outputs[3 * level + 2];
    if (static_cast<int>(class_map.total()) != rows * columns || static_cast<int>(box_map.total()) != 4 * rows * columns) continue;
    const auto* class_score = class_map.ptr<float>();
    const auto* object_score = object_map.ptr<float>();
    const auto* box = box_map.ptr<float>();
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < columns; ++c) {
        const int i = r * columns + c;
        const double score = std::sqrt(std::clamp(class_score[i], 0.0F, 1.0F) * std::clamp(object_score[i], 0.0F, 1.0F));
        if (score < score_threshold) continue;
        const double centre_x = (c + box[4 * i]) * stride, centre_y = (r + box[4 * i + 1]) * stride;
        const double box_width = std::exp(box[4 * i + 2]) * stride, box_height = std::exp(box[4 * i + 3]) * stride;
        boxes->emplace_back((centre_x - 0.5 * box_width) / scale, (centre_y - 0.5 * box_height) / scale, box_width / scale,
                            box_height / scale);
        scores->push_back(static_cast<float>(score));
      }
    }
  }
}

std::vector<FaceDetection> YunetFaceDetector::detect(const cv::Mat& bgr, double score_threshold) {
  std::vector<cv::Rect2d> boxes;
  std::vector<float> scores;
  detect_at_scale(bgr, score_threshold, 1.0, &boxes, &scores);
  const int longer = std::max(bgr.cols, bgr.rows);
  if (longer > kCoarseSide) detect_at_scale(bgr, score_threshold, static_cast<double>(kCoarseSide) / longer, &boxes, &scores);
  std::vector<int> kept;
  cv::dnn::NMSBoxes(boxes, scores, static_cast<float>(score_threshold), kNmsThreshold, kept);
  std::vector<FaceDetection> faces;
  const cv::Rect image(0, 0, bgr.cols, bgr.rows);
  for (const int k : kept) {
    const cv::Rect2d& b = boxes[static_cast<std::size_t>(k)];
    const cv::Rect box = cv::Rect(cv::Point(static_cast<int>(std::floor(b.x)), static_cast<int>(std::floor(b.y))),
                                  cv::Point(static_cast<int>(std::ceil(b.x + b.width)), static_cast<int>(std::ceil(b.y + b.height)))) &
                         image;
    if (box.area() > 0) faces.push_back({box, scores[static_cast<std::size_t>(k)]});
  }
  std::sort(faces.begin(), faces.end(), [](const FaceDetection& a, const FaceDetection& b) { return a.score > b.score; });
  return faces;
}

}  // namespace hanzo::fusion::privacy
