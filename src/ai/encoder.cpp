#include "encoder.hpp"

#include <fmt/format.h>

namespace hanzo::fusion::ai {

void expect_encoder(std::vector<std::pair<std::string, std::vector<int64_t>>>& expected, const EncoderSize& s, EncoderKind kind) {
  auto conv = [&](const std::string& name, int64_t out, int64_t in, int64_t k) { expected.push_back({name, {out, in, k, k}}); };
  conv("block1.conv1.weight", s.c1, 3, 3);
  expect_batch_norm(expected, "block1.bn1", s.c1);
  conv("block1.conv2.weight", s.c1, s.c1, 3);
  expect_batch_norm(expected, "block1.bn2", s.c1);
  const int64_t in[4] = {0, s.c1, s.c2, s.c3}, out[4] = {0, s.c2, s.c3, s.c4};
  for (int b = 1; b <= 3; ++b) {
    const std::string block = fmt::format("block{}", b + 1);
    for (int c = 1; c <= 2; ++c) {
      const int64_t conv_in = c == 1 ? in[b] : out[b];
      if (kind == EncoderKind::kAliked && b >= 2) {  // deformable
        conv(fmt::format("{}.conv{}.offset_conv.weight", block, c), 18, conv_in, 3);
        expected.push_back({fmt::format("{}.conv{}.offset_conv.bias", block, c), {18}});
        conv(fmt::format("{}.conv{}.regular_conv.weight", block, c), out[b], conv_in, 3);
      } else {
        conv(fmt::format("{}.conv{}.weight", block, c), out[b], conv_in, 3);
      }
      expect_batch_norm(expected, fmt::format("{}.bn{}", block, c), out[b]);
    }
    conv(block + ".downsample.weight", out[b], in[b], 1);
    expected.push_back({block + ".downsample.bias", {out[b]}});
  }
  conv("conv1.weight", s.dim / 4, s.c1, 1);
  conv("conv2.weight", s.dim / 4, s.c2, 1);
  conv("conv3.weight", s.dim / 4, s.c3, 1);
  conv("conv4.weight", s.dim / 4, s.c4, 1);
}

FeaturePyramid encode(const at::Tensor& padded, const NetworkWeights& w, EncoderKind kind) {
  const bool aliked = kind == EncoderKind::kAliked;
  auto gate = [&](const at::Tensor& x) { return aliked ? at::selu(x) : at::relu(x); };
  auto pool = [&](const at::Tensor& x, int64_t k) { return aliked ? at::avg_pool2d(x, {k, k}, {k, k}) : at::max_pool2d(x, {k, k}, {k, k}); };
  auto conv = [&](const at::Tensor& x, const std::string& block, int c) {
    const std::string name = fmt::format("{}.conv{}", block, c);
    const bool deformable = aliked && (block == "block3" || block == "block4");
    return deformable ? deformable_convolution(x, w, name) : convolution(x, w, name + ".weight", "", 1);
  };
  auto residual = [&](const at::Tensor& x, const std::string& block) {
    at::Tensor y = gate(batch_norm(conv(x, block, 1), w, block + ".bn1"));
    y = batch_norm(conv(y, block, 2), w, block + ".bn2");
    return gate(y + convolution(x, w, block + ".downsample.weight", block + ".downsample.bias", 0));
  };
  at::Tensor x1 = gate(batch_norm(conv(padded, "block1", 1), w, "block1.bn1"));
  x1 = gate(batch_norm(conv(x1, "block1", 2), w, "block1.bn2"));
  const at::Tensor x2 = residual(pool(x1, 2), "block2");
  const at::Tensor x3 = residual(pool(x2, 4), "block3");
  const at::Tensor x4 = residual(pool(x3, 4), "block4");
  FeaturePyramid pyramid;
  pyramid.levels = {gate(convolution(x1, w, "conv1.weight", "", 0)), gate(convolution(x2, w, "conv2.weight", "", 0)),
                    gate(convolution(x3, w, "conv3.weight", "", 0)), gate(convolution(x4, w, "conv4.weight", "", 0))};
  pyramid.padded_height = padded.size(2);
  pyramid.padded_width = padded.size(3);
  return pyramid;
}

}  // namespace hanzo::fusion::ai
