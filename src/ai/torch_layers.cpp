#include "torch_layers.hpp"

#include <algorithm>

#include <fmt/format.h>
#include <fmt/ranges.h>

namespace hanzo::fusion::ai {

Result<NetworkWeights> NetworkWeights::take(const StateDict& state, const std::vector<std::pair<std::string, std::vector<int64_t>>>& expected,
                                            const std::string& path) {
  NetworkWeights weights;
  for (const auto& [name, shape] : expected) {
    const auto found = state.find(name);
    if (found == state.end()) return Error(fmt::format("{}: no tensor '{}' (not a model of this architecture?)", path, name));
    if (found->second.shape != shape) {
      return Error(fmt::format("{}: tensor '{}' has shape [{}], the architecture expects [{}] (another model size?)", path, name,
                               fmt::join(found->second.shape, ", "), fmt::join(shape, ", ")));
    }
    // A copy the tensor owns (the state_dict may go away).
    weights.tensors_[name] = at::from_blob(const_cast<float*>(found->second.values.data()), shape, at::kFloat).clone();
  }
  return weights;
}

void expect_batch_norm(std::vector<std::pair<std::string, std::vector<int64_t>>>& expected, const std::string& prefix, int64_t channels) {
  for (const char* part : {"weight", "bias", "running_mean", "running_var"}) expected.push_back({fmt::format("{}.{}", prefix, part), {channels}});
}

at::Tensor convolution(const at::Tensor& x, const NetworkWeights& weights, const std::string& weight_name, const std::string& bias_name,
                       int64_t padding) {
  const at::Tensor bias = bias_name.empty() ? at::Tensor() : weights[bias_name];
  return at::conv2d(x, weights[weight_name], bias, {1, 1}, {padding, padding});
}

at::Tensor batch_norm(const at::Tensor& x, const NetworkWeights& weights, const std::string& prefix) {
  return at::batch_norm(x, weights[prefix + ".weight"], weights[prefix + ".bias"], weights[prefix + ".running_mean"],
                        weights[prefix + ".running_var"], /*training=*/false, /*momentum=*/0.1, /*eps=*/1e-5, /*cudnn_enabled=*/false);
}

at::Tensor deformable_convolution(const at::Tensor& x, const NetworkWeights& weights, const std::string& prefix) {
  const int64_t channels = x.size(1), height = x.size(2), width = x.size(3);
  const double max_offset = static_cast<double>(std::max(height, width)) / 4.0;
  const at::Tensor offsets = convolution(x, weights, prefix + ".offset_conv.weight", prefix + ".offset_conv.bias", 1).clamp(-max_offset, max_offset);
  // Sample positions of the 9 taps: y = row - 1 + ky + dy, x = column - 1 + kx + dx.
  const at::Tensor rows = at::arange(height, x.options()).view({1, height, 1});
  const at::Tensor columns = at::arange(width, x.options()).view({1, 1, width});
  const at::Tensor tap = at::arange(9, x.options());
  const at::Tensor tap_y = (at::floor(tap / 3) - 1).view({9, 1, 1}), tap_x = (at::remainder(tap, 3) - 1).view({9, 1, 1});
  const at::Tensor offset = offsets[0].view({9, 2, height, width});
  const at::Tensor y = rows + tap_y + offset.select(1, 0);  // [9, H, W]
  const at::Tensor x_position = columns + tap_x + offset.select(1, 1);
  // grid_sample with align_corners maps -1..1 to the centres of the first and last pixels; zeros
  // outside match deform_conv2d's bilinear_interpolate.
  const at::Tensor grid = at::stack({x_position * (2.0 / static_cast<double>(std::max<int64_t>(width - 1, 1))) - 1.0,
                                     y * (2.0 / static_cast<double>(std::max<int64_t>(height - 1, 1))) - 1.0},
                                    -1)
                              .view({1, 9 * height, width, 2});
  const at::Tensor sampled = at::grid_sampler(x, grid, /*bilinear*/ 0, /*zeros*/ 0, /*align_corners=*/true);  // [1, C, 9H, W]
  const at::Tensor columns_matrix = sampled.view({channels * 9, height * width});
  const at::Tensor& weight = weights[prefix + ".regular_conv.weight"];  // [O, C, 3, 3]
  return at::mm(weight.view({weight.size(0), channels * 9}), columns_matrix).view({1, weight.size(0), height, width});
}

at::Tensor normalize(const at::Tensor& x, int64_t dim) { return x / x.norm(2, dim, /*keepdim=*/true).clamp_min(1e-12); }

at::Tensor sample(const at::Tensor& map, const at::Tensor& grid) {
  const at::Tensor sampled = at::grid_sampler(map, grid.view({1, 1, -1, 2}), 0, 0, true);  // [1, C, 1, N]
  return sampled[0].select(1, 0);
}

}  // namespace hanzo::fusion::ai
