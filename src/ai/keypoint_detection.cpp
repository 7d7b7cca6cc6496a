// Differentiable keypoint detection (DKD, ALIKE sec. III-B) at inference: the upstream
// soft_detect's simple_nms, border removal, threshold / top-k selection and soft-argmax.
#include "learned_network.hpp"
#include "torch_layers.hpp"

namespace hanzo::fusion::ai {
namespace {

// Non-maximum suppression in (2 radius + 1)^2 windows, with two rounds that revive maxima
// suppressed only by suppressed neighbours (SuperPoint's simple_nms).
at::Tensor simple_nms(const at::Tensor& scores, int64_t radius) {
  auto max_pool = [&](const at::Tensor& x) { return at::max_pool2d(x, {2 * radius + 1, 2 * radius + 1}, {1, 1}, {radius, radius}); };
  const at::Tensor zeros = at::zeros_like(scores);
  at::Tensor max_mask = scores == max_pool(scores);
  for (int round = 0; round < 2; ++round) {
    const at::Tensor suppressed = max_pool(max_mask.to(at::kFloat)) > 0;
    const at::Tensor kept_scores = at::where(suppressed, zeros, scores);
    const at::Tensor new_max = kept_scores == max_pool(kept_scores);
    max_mask = max_mask | (new_max & suppressed.logical_not());
  }
  return at::where(max_mask, scores, zeros);
}

}  // namespace

std::pair<at::Tensor, at::Tensor> detect_keypoints(const at::Tensor& score_map, const LearnedFeatureConfig& config) {
  const int64_t radius = config.nms_radius, height = score_map.size(2), width = score_map.size(3);
  at::Tensor nms = simple_nms(score_map, radius);
  nms.slice(2, 0, radius + 1).zero_();
  nms.slice(3, 0, radius + 1).zero_();
  nms.slice(2, height - radius, height).zero_();
  nms.slice(3, width - radius, width).zero_();
  const at::Tensor flat = nms.reshape({-1});
  at::Tensor indices;
  if (config.score_threshold > 0.0F) {
    at::Tensor mask = flat > config.score_threshold;
    if (mask.sum().item<int64_t>() == 0) mask = flat > score_map.mean().item<float>();
    indices = mask.nonzero().select(1, 0);
    if (indices.size(0) > config.max_keypoints) {
      const at::Tensor order = std::get<1>(score_map.reshape({-1}).index_select(0, indices).sort(/*dim=*/0, /*descending=*/true));
      indices = indices.index_select(0, order.slice(0, 0, config.max_keypoints));
    }
  } else {
    indices = std::get<1>(flat.topk(std::min<int64_t>(config.max_keypoints, flat.size(0))));
  }
  at::Tensor keypoints = at::stack({at::remainder(indices, width), at::floor_divide(indices, width)}, 1).to(at::kFloat);
  if (config.subpixel && indices.size(0) > 0) {
    const int64_t kernel = 2 * radius + 1;
    const at::Tensor patches = at::im2col(score_map, {kernel, kernel}, {1, 1}, {radius, radius}, {1, 1})[0].t();  // [H W, k^2]
    const at::Tensor patch_scores = patches.index_select(0, indices);
    const at::Tensor max_value = std::get<0>(patch_scores.max(1, /*keepdim=*/true));
    const at::Tensor weights = ((patch_scores - max_value) / 0.1).exp();  // temperature 0.1
    const at::Tensor offsets = at::arange(-radius, radius + 1, score_map.options());
    // Row k of the grid is (x, y) of window element k = ky * kernel + kx.
    const at::Tensor grid = at::stack({offsets.repeat({kernel}), offsets.repeat_interleave(kernel)}, 1);
    keypoints = keypoints + weights.mm(grid) / weights.sum(1, /*keepdim=*/true);
  }
  const at::Tensor wh = at::tensor({static_cast<float>(width - 1), static_cast<float>(height - 1)}, score_map.options()).view({1, 2});
  const at::Tensor normalized = keypoints / wh * 2 - 1;
  const at::Tensor scores = indices.size(0) > 0 ? sample(score_map, normalized).select(0, 0) : at::zeros({0}, score_map.options());
  return {normalized, scores};
}

}  // namespace hanzo::fusion::ai
