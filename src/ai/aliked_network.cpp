// ALIKED (Zhao et al., IEEE TIM 2023): encoder, aggregation, score head and the sparse deformable
// descriptor head, with the upstream state_dict's tensor names.
#include <cmath>

#include <fmt/format.h>

#include "learned_network.hpp"
#include "encoder.hpp"
#include "torch_layers.hpp"

namespace hanzo::fusion::ai {
namespace {

struct AlikedSize {
  int64_t c1, c2, c3, c4, dim, positions;
};

AlikedSize aliked_size(LearnedModel model) {
  switch (model) {
    case LearnedModel::kAlikedT16: return {8, 16, 32, 64, 64, 16};
    case LearnedModel::kAlikedN32: return {16, 32, 64, 128, 128, 32};
    default: return {16, 32, 64, 128, 128, 16};  // n16, n16rot
  }
}

using Expected = std::vector<std::pair<std::string, std::vector<int64_t>>>;

class AlikedNetwork final : public LearnedFeatureExtractor::Network {
 public:
  AlikedNetwork(AlikedSize size, NetworkWeights weights) : size_(size), weights_(std::move(weights)) {}

  static Expected expected(const AlikedSize& s) {
    Expected e;
    expect_encoder(e, {s.c1, s.c2, s.c3, s.c4, s.dim}, EncoderKind::kAliked);
    auto conv = [&](const std::string& name, int64_t out, int64_t in, int64_t k) { e.push_back({name, {out, in, k, k}}); };
    conv("score_head.0.weight", 8, s.dim, 1);
    conv("score_head.2.weight", 4, 8, 3);
    conv("score_head.4.weight", 4, 4, 3);
    conv("score_head.6.weight", 1, 4, 3);
    e.push_back({"desc_head.agg_weights", {s.positions, s.dim, s.dim}});
    conv("desc_head.offset_conv.0.weight", 2 * s.positions, s.dim, 3);
    e.push_back({"desc_head.offset_conv.0.bias", {2 * s.positions}});
    conv("desc_head.offset_conv.2.weight", 2 * s.positions, 2 * s.positions, 1);
    e.push_back({"desc_head.offset_conv.2.bias", {2 * s.positions}});
    conv("desc_head.sf_conv.weight", s.dim, s.dim, 1);
    return e;
  }

  DenseMaps dense(const at::Tensor& image) const override {
    const int64_t height = image.size(2), width = image.size(3);
    // Pad to a multiple of 32 with replicated edges, centred (RAFT's InputPadder).
    const int64_t pad_h = (32 - height % 32) % 32, pad_w = (32 - width % 32) % 32;
    const int64_t left = pad_w / 2, top = pad_h / 2;
    const at::Tensor padded = at::replication_pad2d(image, {left, pad_w - left, top, pad_h - top});
    const NetworkWeights& w = weights_;
    DenseMaps maps;
    maps.features = encode(padded, w, EncoderKind::kAliked);
    FeaturePyramid& pyramid = maps.features;
    pyramid.top = top;
    pyramid.left = left;
    pyramid.height = height;
    pyramid.width = width;
    // Score head on the aggregated features; its first layer is a 1x1 convolution (projected).
    at::Tensor score = at::selu(pyramid.project(w["score_head.0.weight"].flatten(1)));
    score = at::selu(convolution(score, w, "score_head.2.weight", "", 1));
    score = at::selu(convolution(score, w, "score_head.4.weight", "", 1));
    score = at::sigmoid(convolution(score, w, "score_head.6.weight", "", 1));
    maps.score_map = score.slice(2, top, top + height).slice(3, left, left + width).contiguous();
    return maps;
  }

  // SDDH (paper eq. 6-8): offsets of M positions from the keypoint's 3x3 patch of the normalized
  // features, the features sampled there, a 1x1 convolution + SELU, and a learned weighted sum
  // over the positions.
  at::Tensor describe(const DenseMaps& maps, const at::Tensor& keypoints, bool /*subpixel*/) const override {
    const FeaturePyramid& pyramid = maps.features;
    const int64_t channels = pyramid.channels(), count = keypoints.size(0), positions = size_.positions;
    if (count == 0) return at::zeros({0, channels}, keypoints.options());
    const at::Tensor pixels = pyramid.to_pixels(keypoints);  // [N, 2] (x, y)
    const at::Tensor integer = pixels.to(at::kLong);
    auto unit = [](const at::Tensor& features) { return normalize(features, 1); };
    // 3x3 patches around the keypoints' pixels (zeros outside the image), taps row-major.
    const at::Tensor steps = at::arange(-1, 2, integer.options());
    const at::Tensor taps = at::stack({steps.repeat({3}), steps.repeat_interleave(3)}, 1);  // [9, 2] (dx, dy)
    const at::Tensor tap_pixels = (integer.unsqueeze(1) + taps.unsqueeze(0)).reshape({count * 9, 2});
    const at::Tensor patches = unit(pyramid.at_pixels(tap_pixels)).view({count, 3, 3, channels}).permute({0, 3, 1, 2}).contiguous();
    const double max_offset = static_cast<double>(std::max(pyramid.height, pyramid.width)) / 4.0;
    const NetworkWeights& w = weights_;
    at::Tensor offsets = at::selu(convolution(patches, w, "desc_head.offset_conv.0.weight", "desc_head.offset_conv.0.bias", 0));
    offsets = convolution(offsets, w, "desc_head.offset_conv.2.weight", "desc_head.offset_conv.2.bias", 0).clamp(-max_offset, max_offset);
    const at::Tensor offset = offsets.view({count, 2, positions}).permute({0, 2, 1});  // [N, M, 2] (x, y)
    const at::Tensor sample_positions = (pixels.unsqueeze(1) + offset).reshape({count * positions, 2});
    const at::Tensor sampled = pyramid.interpolate(sample_positions, unit);  // [N M, C]
    const at::Tensor per_position = at::selu(at::mm(sampled, w["desc_head.sf_conv.weight"].flatten(1).t()));  // 1x1 conv, [N M, C]
    // descriptor_d = sum_{p, c} features[n, p, c] agg[p, c, d]
    const at::Tensor descriptors = at::mm(per_position.reshape({count, positions * channels}),
                                          w["desc_head.agg_weights"].reshape({positions * channels, channels}));
    return normalize(descriptors, 1);
  }

  int descriptor_size() const override { return static_cast<int>(size_.dim); }

 private:
  AlikedSize size_;
  NetworkWeights weights_;
};

}  // namespace

Result<std::unique_ptr<LearnedFeatureExtractor::Network>> make_aliked_network(LearnedModel model, const StateDict& state, const std::string& path) {
  const AlikedSize size = aliked_size(model);
  NetworkWeights weights;
  HANZO_ASSIGN_OR_RETURN(weights, NetworkWeights::take(state, AlikedNetwork::expected(size), path));
  return std::unique_ptr<LearnedFeatureExtractor::Network>(std::make_unique<AlikedNetwork>(size, std::move(weights)));
}

}  // namespace hanzo::fusion::ai
