#pragma once
// LearnedFeatureExtractor: learned keypoints and descriptors on the CPU (libtorch), behind the
// vision::FeatureExtractor interface ORB uses.
//
//   ALIKED (Zhao et al., IEEE TIM 2023): a 4-block encoder (plain 3x3 convolutions in blocks 1-2,
//     deformable ones in blocks 3-4, SELU, average pooling), multi-scale aggregation to a
//     full-resolution feature map, a score head, and the sparse deformable descriptor head
//     (SDDH): per keypoint, M sample positions predicted from its 3x3 feature patch, the
//     features there (bilinear) weighted and summed into the descriptor (paper eq. 6-8).
//     Models aliked-t16, aliked-n16, aliked-n16rot, aliked-n32 (descriptors of 64 / 128 floats).
//   ALIKE (Zhao et al., IEEE TMM 2022): the same layout with plain convolutions, ReLU and max
//     pooling, the descriptor map sampled at the keypoints. Models alike-t, alike-s, alike-n,
//     alike-l (64 / 96 / 128 / 128 floats).
// Keypoints by differentiable keypoint detection (DKD, ALIKE sec. III-B): non-maximum
// suppression of the score map in (2 nms_radius + 1)^2 windows (two suppression rounds), borders
// of nms_radius + 1 pixels cleared, scores above score_threshold kept (the best max_keypoints of
// them; when none passes, those above the map's mean), then, with subpixel, a soft-argmax over
// the window (temperature 0.1) and the score sampled bilinearly there.
//
// Input: an 8-bit grey, BGR or BGRA image (grey is repeated into RGB), scaled to [0, 1] RGB and
// padded to a multiple of 32 (ALIKED: replicated edges, centred; ALIKE: zeros right and
// bottom). Output: keypoints in pixels (cv::KeyPoint::response = score, size = 2 nms_radius + 1,
// octave 0), unit-length CV_32FC1 descriptors.
//
// Weights: the upstream PyTorch state_dicts (`<model>.pth`, BSD-3-Clause), read by
// read_state_dict(); every tensor of the architecture must be present with its shape (errors
// name the file and the tensor). Failure: a missing or wrong model file, an image smaller than
// 64 x 64 pixels or of another type, a mask of another size.

#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/vision/feature_extractor.hpp"

namespace hanzo::fusion::ai {

enum class LearnedModel { kAlikedT16, kAlikedN16, kAlikedN16Rot, kAlikedN32, kAlikeT, kAlikeS, kAlikeN, kAlikeL };

/// "aliked-t16", "aliked-n16", "aliked-n16rot", "aliked-n32", "alike-t", "alike-s", "alike-n", "alike-l".
std::string_view to_string(LearnedModel model);
std::optional<LearnedModel> learned_model_from_name(std::string_view name);
/// Every model, in the order above.
const std::vector<LearnedModel>& all_learned_models();

/// Where a model's weights are: `path` when not empty; else `<name>.pth` found by
/// find_model_file() in $HANZO_FUSION_MODELS or one of its folders. Fails naming what was looked
/// for when none exists.
Result<std::string> find_learned_model(LearnedModel model, const std::string& path = {});

struct LearnedFeatureConfig {
  LearnedModel model = LearnedModel::kAlikedT16;
  /// The .pth file; empty: find_learned_model().
  std::string model_path;
  /// Keypoints with scores above this (0..1) are kept; <= 0: the max_keypoints best, whatever
  /// their score.
  float score_threshold = 0.2F;
  /// At most this many keypoints (the best scores), >= 1.
  int max_keypoints = 2000;
  /// Non-maximum suppression radius (pixels), 1..8; both models were trained with 2.
  int nms_radius = 2;
  /// Soft-argmax refinement of keypoints to sub-pixel positions.
  bool subpixel = true;
  /// CPU threads of the network (0: one per core). libtorch's thread pool is per process: the
  /// last extractor loaded sets it.
  int threads = 0;
};

Status validate(const LearnedFeatureConfig& config);

/// Dense outputs of one image, for checks against other implementations.
struct LearnedFeatureMaps {
  cv::Mat score_map;  ///< CV_32FC1, the image's size, scores in (0, 1)
  vision::ImageFeatures features;
};

class LearnedFeatureExtractor final : public vision::FeatureExtractor {
 public:
  static Result<std::unique_ptr<LearnedFeatureExtractor>> load(const LearnedFeatureConfig& config);
  ~LearnedFeatureExtractor() override;

  Result<vision::ImageFeatures> extract(const cv::Mat& image, const cv::Mat& mask = cv::Mat()) const override;
  /// extract() and the score map.
  Result<LearnedFeatureMaps> extract_with_maps(const cv::Mat& image, const cv::Mat& mask = cv::Mat()) const;
  std::string name() const override { return std::string(to_string(config_.model)); }
  int descriptor_type() const override { return CV_32FC1; }
  const LearnedFeatureConfig& config() const { return config_; }
  /// The weights' file.
  const std::string& model_path() const { return model_path_; }
  int descriptor_size() const;

  class Network;

 private:
  LearnedFeatureExtractor(LearnedFeatureConfig config, std::string model_path, std::unique_ptr<Network> network);
  LearnedFeatureConfig config_;
  std::string model_path_;
  std::unique_ptr<Network> network_;
};

}  // namespace hanzo::fusion::ai
