#pragma once
// The networks behind LearnedFeatureExtractor: dense maps of an image, descriptors of keypoints.

#include <memory>

#include <ATen/ATen.h>

#include "hanzo/fusion/ai/learned_features.hpp"
#include "hanzo/fusion/ai/state_dict.hpp"
#include "feature_pyramid.hpp"

namespace hanzo::fusion::ai {

struct DenseMaps {
  at::Tensor score_map;    ///< [1, 1, H, W], sigmoid scores
  FeaturePyramid features;  ///< the aggregated features, for the descriptors
};

class LearnedFeatureExtractor::Network {
 public:
  virtual ~Network() = default;
  /// `image`: [1, 3, H, W] RGB in [0, 1]; the maps have the image's size (padding undone).
  virtual DenseMaps dense(const at::Tensor& image) const = 0;
  /// Unit descriptors [N, D] of keypoints at normalized positions [N, 2] ((x, y) in [-1, 1]
  /// over the image's corner pixels); `subpixel`: ALIKE samples its map bilinearly, else at the
  /// pixel.
  virtual at::Tensor describe(const DenseMaps& maps, const at::Tensor& keypoints, bool subpixel) const = 0;
  virtual int descriptor_size() const = 0;
};

Result<std::unique_ptr<LearnedFeatureExtractor::Network>> make_aliked_network(LearnedModel model, const StateDict& state, const std::string& path);
Result<std::unique_ptr<LearnedFeatureExtractor::Network>> make_alike_network(LearnedModel model, const StateDict& state, const std::string& path);

/// DKD (learned_features.hpp): keypoints at normalized positions [N, 2] and their scores [N].
std::pair<at::Tensor, at::Tensor> detect_keypoints(const at::Tensor& score_map, const LearnedFeatureConfig& config);

}  // namespace hanzo::fusion::ai
