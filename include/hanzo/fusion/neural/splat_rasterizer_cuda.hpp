#pragma once
// The splat rasterizer (splat_rasterizer.hpp: equations, conventions, outputs) on a CUDA device.
// The per-Gaussian and per-pixel arithmetic is the CPU's own (one source compiled for both);
// the schedule is the GPU's: a radix sort of (tile, depth) keys, a 16 x 16 thread block per
// tile, gradients summed with atomics. Renders agree with the CPU's to float rounding; the
// gradients' sums depend on the thread schedule (the CPU's do not), so replay-deterministic
// work (sessions) uses the CPU.
//
// Built when the CMake option HANZO_FUSION_CUDA is on (default: on when nvcc is found); without
// it, or without a device or driver, create() fails with the reason and callers use the CPU.
// One instance serves one thread at a time.

#include <memory>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/neural/gaussian_cloud.hpp"
#include "hanzo/fusion/neural/splat_rasterizer.hpp"

namespace hanzo::fusion::neural {

/// Where a rasterizer runs: `auto` picks CUDA when a device is present, else the CPU.
enum class SplatDevice { kCpu, kCuda, kAuto };
/// "cpu" | "cuda" | "auto"; fails naming the value otherwise.
Result<SplatDevice> parse_splat_device(const std::string& text);

/// A rendered view's images (CudaSplatRasterizer::render_view): width x height pixels, row-major.
struct SplatView {
  int width = 0, height = 0;
  std::vector<float> image;  ///< RGB, 3 floats a pixel
  std::vector<float> depth;  ///< empty unless asked for
  std::vector<float> alpha;  ///< empty unless asked for
};

class CudaSplatRasterizer {
 public:
  /// Whether this build has the CUDA rasterizer and a device is present; `reason` says why not.
  static bool available(std::string* reason = nullptr);
  /// A rasterizer on CUDA device `device`; fails when unavailable (the reason in the error).
  static Result<CudaSplatRasterizer> create(int device = 0);

  CudaSplatRasterizer(CudaSplatRasterizer&&) noexcept;
  CudaSplatRasterizer& operator=(CudaSplatRasterizer&&) noexcept;
  ~CudaSplatRasterizer();

  /// Copies the cloud to the device; renders use it until the next upload.
  Status upload(const GaussianCloud& cloud);
  /// render_splats of the uploaded cloud: image, depth, alpha, final_transmittance,
  /// contributors and the per-Gaussian fields; the tile lists stay on the device (tile_range
  /// and tile_gaussians empty).
  Result<SplatRender> render(const SplatCamera& camera, const RasterizerConfig& config);
  /// The view alone, for display (the `render` command, viewers): render_splats' image (3 floats
  /// a pixel, row-major), and its depth and alpha when `with_depth_and_alpha`, written into
  /// `view`'s arrays (resized; keep one SplatView across calls to reuse them). Nothing per
  /// Gaussian comes back, so backward() needs a render() after it.
  Status render_view(const SplatCamera& camera, const RasterizerConfig& config, SplatView& view, bool with_depth_and_alpha = false);
  /// render_splats_backward of the last render (same camera and settings): adds to `gradients`
  /// (sized like the uploaded cloud).
  Status backward(const std::vector<float>& loss_gradient_image, GaussianGradients& gradients);

  const std::string& device_name() const;

 private:
  struct State;
  explicit CudaSplatRasterizer(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace hanzo::fusion::neural
