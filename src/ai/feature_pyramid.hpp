#pragma once
// FeaturePyramid: ALIKE's and ALIKED's aggregated features (ALIKE eq. 1: cat of the four encoder
// levels, each gated and upsampled bilinearly, align_corners, to the padded image's size) without
// building them at full resolution, where the 64-128 channels cost more memory traffic than the
// whole encoder: per-pixel linear maps of them are computed level by level before upsampling
// (upsampling is linear per channel, so W cat(l_i) = sum_i up(W_i l_i) exactly), and features at
// given pixels are gathered and interpolated from the levels. Results agree with the full-size
// computation to float rounding.

#include <array>
#include <functional>

#include <ATen/ATen.h>

namespace hanzo::fusion::ai {

struct FeaturePyramid {
  /// Gated levels [1, C_l, H_l, W_l]: level 0 at the padded image's resolution, levels 1-3 at 1/2,
  /// 1/8 and 1/32 of it.
  std::array<at::Tensor, 4> levels;
  int64_t padded_height = 0, padded_width = 0;
  /// The image inside the padded map: its top-left pixel and size.
  int64_t top = 0, left = 0, height = 0, width = 0;

  int64_t channels() const;
  /// Normalized positions [N, 2] ((x, y) in [-1, 1] over the image's corner pixels, as DKD gives
  /// keypoints) in image pixels.
  at::Tensor to_pixels(const at::Tensor& normalized) const;
  /// weight [O, channels()] applied as a 1x1 convolution to the full-resolution features:
  /// [1, O, padded_height, padded_width].
  at::Tensor project(const at::Tensor& weight) const;
  /// Features [P, channels()] at integer image pixels [P, 2] ((x, y), kLong); zeros for pixels
  /// outside the image.
  at::Tensor at_pixels(const at::Tensor& pixels) const;
  /// The map of `per_pixel` (features [P, C] -> [P, D], zero for zero features) sampled
  /// bilinearly at image positions [P, 2] ((x, y) pixels, float), as grid_sample with
  /// align_corners and zeros outside the image does on the image-size map: [P, D].
  at::Tensor interpolate(const at::Tensor& positions, const std::function<at::Tensor(const at::Tensor&)>& per_pixel) const;
};

}  // namespace hanzo::fusion::ai
