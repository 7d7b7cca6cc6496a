#pragma once
// Image quality against a reference: PSNR and SSIM (Wang et al., IEEE TIP 2004: 11 x 11
// Gaussian window, sigma 1.5, C1 = 0.01^2, C2 = 0.03^2 for values in 0..1, zero padding at the
// border, averaged over pixels and channels, as the 3D Gaussian splatting and NeRF evaluations
// compute it), and SSIM's gradient for training losses.
//
// Images are RGB float rows (3 floats a pixel, 0..1) of width x height; mismatched sizes are a
// programming error (asserted by the callers' shapes, not checked here).

#include <string>
#include <vector>

namespace hanzo::fusion::neural {

struct RgbImage {
  int width = 0, height = 0;
  std::vector<float> pixels;  ///< RGB, row-major, 0..1
};

/// 10 log10(1 / MSE) over all channels; infinity for identical images.
double psnr(const std::vector<float>& image, const std::vector<float>& reference);

/// Mean SSIM over pixels and channels; with `gradient` (resized to the image), dSSIM/dimage.
double ssim(const std::vector<float>& image, const std::vector<float>& reference, int width, int height, std::vector<float>* gradient = nullptr);

/// Scores of rendered views against held-back images.
struct ViewScore {
  std::string name;
  double psnr = 0.0, ssim = 0.0;
};
struct EvaluationSummary {
  std::vector<ViewScore> views;
  double mean_psnr = 0.0, mean_ssim = 0.0;
  double seconds_per_view = 0.0;  ///< rendering only
};

}  // namespace hanzo::fusion::neural
