#include "feature_pyramid.hpp"

namespace hanzo::fusion::ai {

int64_t FeaturePyramid::channels() const {
  int64_t total = 0;
  for (const at::Tensor& level : levels) total += level.size(1);
  return total;
}

at::Tensor FeaturePyramid::to_pixels(const at::Tensor& normalized) const {
  const at::Tensor wh = at::tensor({static_cast<float>(width - 1), static_cast<float>(height - 1)}, normalized.options()).view({1, 2});
  return (normalized + 1) / 2 * wh;
}

at::Tensor FeaturePyramid::project(const at::Tensor& weight) const {
  at::Tensor sum;
  int64_t column = 0;
  for (const at::Tensor& level : levels) {
    const int64_t count = level.size(1);
    const at::Tensor part = weight.slice(1, column, column + count).reshape({weight.size(0), count, 1, 1});
    column += count;
    at::Tensor projected = at::conv2d(level, part);
    if (projected.size(2) != padded_height) projected = at::upsample_bilinear2d(projected, {padded_height, padded_width}, /*align_corners=*/true);
    sum = sum.defined() ? sum + projected : projected;
  }
  return sum;
}

at::Tensor FeaturePyramid::at_pixels(const at::Tensor& pixels) const {
  const at::Tensor x = pixels.select(1, 0), y = pixels.select(1, 1);
  const at::Tensor inside = (x >= 0) & (x < width) & (y >= 0) & (y < height);
  const at::Tensor padded_x = x.clamp(0, width - 1) + left, padded_y = y.clamp(0, height - 1) + top;
  std::vector<at::Tensor> parts;
  // Level 0 at full resolution: a gather.
  const at::Tensor& full = levels[0];
  parts.push_back(full[0].reshape({full.size(1), -1}).index_select(1, padded_y * padded_width + padded_x).t());
  // Coarser levels: upsampling with align_corners puts output pixel u at u (in - 1) / (out - 1)
  // of the input, which grid_sample with align_corners reaches from 2 u / (out - 1) - 1.
  const at::Tensor grid = at::stack({padded_x.to(at::kFloat) * (2.0 / static_cast<double>(padded_width - 1)) - 1.0,
                                     padded_y.to(at::kFloat) * (2.0 / static_cast<double>(padded_height - 1)) - 1.0},
                                    1)
                              .view({1, 1, -1, 2});
  for (std::size_t l = 1; l < levels.size(); ++l) {
    parts.push_back(at::grid_sampler(levels[l], grid, 0, 0, /*align_corners=*/true)[0].select(1, 0).t());
  }
  return at::cat(parts, 1) * inside.unsqueeze(1).to(at::kFloat);
}

at::Tensor FeaturePyramid::interpolate(const at::Tensor& positions, const std::function<at::Tensor(const at::Tensor&)>& per_pixel) const {
  const at::Tensor x = positions.select(1, 0), y = positions.select(1, 1);
  const at::Tensor x0 = at::floor(x), y0 = at::floor(y);
  const at::Tensor fx = (x - x0).unsqueeze(1), fy = (y - y0).unsqueeze(1);
  const at::Tensor ix = x0.to(at::kLong), iy = y0.to(at::kLong);
  auto corner = [&](int dx, int dy) { return per_pixel(at_pixels(at::stack({ix + dx, iy + dy}, 1))); };
  return corner(0, 0) * ((1 - fx) * (1 - fy)) + corner(1, 0) * (fx * (1 - fy)) + corner(0, 1) * ((1 - fx) * fy) + corner(1, 1) * (fx * fy);
}

}  // namespace hanzo::fusion::ai
