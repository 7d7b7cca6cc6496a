#pragma once
// The 4-block encoder ALIKE and ALIKED share (ALIKE fig. 2): block 1 two 3x3 convolutions with
// batch norm at full resolution, blocks 2-4 residual blocks (two 3x3 convolutions with batch norm
// and a 1x1 shortcut) after pooling by 2, 4 and 4; each level then a 1x1 convolution to dim / 4
// channels and the gate. ALIKE: ReLU, max pooling, plain convolutions. ALIKED: SELU, average
// pooling, deformable convolutions in blocks 3 and 4.

#include <string>
#include <utility>
#include <vector>

#include <ATen/ATen.h>

#include "feature_pyramid.hpp"
#include "torch_layers.hpp"

namespace hanzo::fusion::ai {

enum class EncoderKind { kAlike, kAliked };

struct EncoderSize {
  int64_t c1, c2, c3, c4, dim;
};

/// The encoder's tensors (names as in the upstream state_dicts) and their shapes.
void expect_encoder(std::vector<std::pair<std::string, std::vector<int64_t>>>& expected, const EncoderSize& size, EncoderKind kind);

/// The gated levels of `padded` [1, 3, H, W] (H, W multiples of 32); the pyramid's image window
/// is left for the caller.
FeaturePyramid encode(const at::Tensor& padded, const NetworkWeights& weights, EncoderKind kind);

}  // namespace hanzo::fusion::ai
