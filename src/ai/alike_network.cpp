// ALIKE (Zhao et al., IEEE TMM 2022): encoder, aggregation and a joint head whose last channel is
// the score map, with the upstream state_dict's tensor names.
#include <fmt/format.h>

#include "learned_network.hpp"
#include "encoder.hpp"
#include "torch_layers.hpp"

namespace hanzo::fusion::ai {
namespace {

struct AlikeSize {
  int64_t c1, c2, c3, c4, dim;
  bool single_head;
};

AlikeSize alike_size(LearnedModel model) {
  switch (model) {
    case LearnedModel::kAlikeT: return {8, 16, 32, 64, 64, true};
    case LearnedModel::kAlikeS: return {8, 16, 48, 96, 96, true};
    case LearnedModel::kAlikeN: return {16, 32, 64, 128, 128, true};
    default: return {32, 64, 128, 128, 128, false};  // alike-l
  }
}

using Expected = std::vector<std::pair<std::string, std::vector<int64_t>>>;

class AlikeNetwork final : public LearnedFeatureExtractor::Network {
 public:
  AlikeNetwork(AlikeSize size, NetworkWeights weights) : size_(size), weights_(std::move(weights)) {}

  static Expected expected(const AlikeSize& s) {
    Expected e;
    expect_encoder(e, {s.c1, s.c2, s.c3, s.c4, s.dim}, EncoderKind::kAlike);
    auto conv = [&](const std::string& name, int64_t out, int64_t in, int64_t k) { e.push_back({name, {out, in, k, k}}); };
    if (!s.single_head) conv("convhead1.weight", s.dim, s.dim, 1);
    conv("convhead2.weight", s.dim + 1, s.dim, 1);
    return e;
  }

  DenseMaps dense(const at::Tensor& image) const override {
    const int64_t height = image.size(2), width = image.size(3);
    // Zeros right and bottom up to a multiple of 32 (upstream's extract_dense_map).
    const int64_t pad_h = (32 - height % 32) % 32, pad_w = (32 - width % 32) % 32;
    const at::Tensor padded = at::constant_pad_nd(image, {0, pad_w, 0, pad_h}, 0.0);
    const NetworkWeights& w = weights_;
    DenseMaps maps;
    maps.features = encode(padded, w, EncoderKind::kAlike);
    FeaturePyramid& pyramid = maps.features;
    pyramid.height = height;
    pyramid.width = width;
    // The score is the head's last channel: with one head a projection of the features; alike-l's
    // hidden 1x1 layer (with ReLU) is computed at full resolution.
    const at::Tensor score_row = w["convhead2.weight"].flatten(1).slice(0, size_.dim, size_.dim + 1);
    const at::Tensor logit = size_.single_head ? pyramid.project(score_row)
                                               : at::conv2d(at::relu(pyramid.project(w["convhead1.weight"].flatten(1))), score_row.view({1, size_.dim, 1, 1}));
    maps.score_map = at::sigmoid(logit).slice(2, 0, height).slice(3, 0, width).contiguous();
    return maps;
  }

  // The normalized descriptor map at the keypoints: bilinear with sub-pixel keypoints (then
  // normalized again), else at the keypoint's pixel.
  at::Tensor describe(const DenseMaps& maps, const at::Tensor& keypoints, bool subpixel) const override {
    const FeaturePyramid& pyramid = maps.features;
    if (keypoints.size(0) == 0) return at::zeros({0, size_.dim}, keypoints.options());
    const at::Tensor descriptor_rows = weights_["convhead2.weight"].flatten(1).slice(0, 0, size_.dim).t();  // [C, dim]
    const at::Tensor hidden = size_.single_head ? at::Tensor() : weights_["convhead1.weight"].flatten(1).t();
    auto descriptor = [&](const at::Tensor& features) {
      const at::Tensor input = hidden.defined() ? at::relu(at::mm(features, hidden)) : features;
      return normalize(at::mm(input, descriptor_rows), 1);
    };
    const at::Tensor pixels = pyramid.to_pixels(keypoints);
    const at::Tensor descriptors = subpixel ? pyramid.interpolate(pixels, descriptor) : descriptor(pyramid.at_pixels(pixels.to(at::kLong)));
    return normalize(descriptors, 1);
  }

  int descriptor_size() const override { return static_cast<int>(size_.dim); }

 private:
  AlikeSize size_;
  NetworkWeights weights_;
};

}  // namespace

Result<std::unique_ptr<LearnedFeatureExtractor::Network>> make_alike_network(LearnedModel model, const StateDict& state, const std::string& path) {
  const AlikeSize size = alike_size(model);
  NetworkWeights weights;
  HANZO_ASSIGN_OR_RETURN(weights, NetworkWeights::take(state, AlikeNetwork::expected(size), path));
  return std::unique_ptr<LearnedFeatureExtractor::Network>(std::make_unique<AlikeNetwork>(size, std::move(weights)));
}

}  // namespace hanzo::fusion::ai
