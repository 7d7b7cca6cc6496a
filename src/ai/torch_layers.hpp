#pragma once
// The layers of the learned networks as functions of ATen tensors (NCHW, float32, batch 1), the
// weights taken by name from a state_dict (torch's own module semantics reproduced: see each).

#include <map>
#include <string>
#include <utility>
#include <vector>

#include <ATen/ATen.h>

#include "hanzo/fusion/ai/state_dict.hpp"
#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::ai {

/// A state_dict's tensors by name, each checked against the shape the architecture expects.
class NetworkWeights {
 public:
  /// (name, shape) of every tensor the network uses; fails naming the first missing one or the
  /// first of another shape.
  static Result<NetworkWeights> take(const StateDict& state, const std::vector<std::pair<std::string, std::vector<int64_t>>>& expected,
                                     const std::string& path);
  const at::Tensor& operator[](const std::string& name) const { return tensors_.at(name); }

 private:
  std::map<std::string, at::Tensor> tensors_;
};

/// The (name, shape) entries of a BatchNorm2d called `prefix` with `channels`.
void expect_batch_norm(std::vector<std::pair<std::string, std::vector<int64_t>>>& expected, const std::string& prefix, int64_t channels);

/// nn.Conv2d (stride 1): `bias_name` empty for none.
at::Tensor convolution(const at::Tensor& x, const NetworkWeights& weights, const std::string& weight_name, const std::string& bias_name,
                       int64_t padding);
/// nn.BatchNorm2d in evaluation mode (running statistics, eps 1e-5).
at::Tensor batch_norm(const at::Tensor& x, const NetworkWeights& weights, const std::string& prefix);
/// ALIKED's DeformableConv2d (3x3, stride 1, padding 1, no mask, no bias): offsets from
/// `<prefix>.offset_conv` clamped to +-max(H, W) / 4, then torchvision's deform_conv2d (Dai et
/// al. 2017): each output pixel p sums w_k x(p + p_k + dp_k) over the 9 taps, x sampled
/// bilinearly with zeros outside the image; offset channels (2k, 2k + 1) = (dy, dx) of tap k.
at::Tensor deformable_convolution(const at::Tensor& x, const NetworkWeights& weights, const std::string& prefix);
/// F.normalize(x, p=2, dim): x / max(||x||, 1e-12).
at::Tensor normalize(const at::Tensor& x, int64_t dim);
/// Bilinear sampling of `map` [1, C, H, W] at normalized positions `grid` [N, 2] ((x, y) in
/// [-1, 1] over the map's corner pixels, align_corners): [C, N].
at::Tensor sample(const at::Tensor& map, const at::Tensor& grid);

}  // namespace hanzo::fusion::ai
