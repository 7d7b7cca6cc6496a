#pragma once
// SplatTrainer: optimizes a GaussianCloud so that its renders match posed images (3D Gaussian
// splatting, Kerbl et al., SIGGRAPH 2023, Sec. 5).
//
// Each step renders one view (splat_rasterizer.hpp), takes the loss
//   L = (1 - ssim_weight) |render - image|_1 + ssim_weight (1 - SSIM(render, image))   (paper eq. 7)
// (means over pixels and channels), back-propagates it and moves every parameter by Adam with
// its own learning rate; the positions' rate decays exponentially from position_lr_initial to
// position_lr_final over the run and is multiplied by the scene extent. The spherical harmonics'
// active degree grows by one every sh_degree_interval steps.
// Adaptive density control (paper Sec. 5.2), every densify_interval steps between densify_from
// and densify_until: Gaussians whose mean view-space gradient (normalized device coordinates)
// reaches densify_gradient_threshold are cloned when small (largest scale <= dense_percent x
// extent) and split in two (scales / 1.6, positions drawn from the Gaussian) when large; those
// with opacity under min_opacity, or (after the first opacity reset) larger than a tenth of the
// extent or drawn wider than max_screen_share of the image since the last densification, are
// removed (the floaters); max_gaussians caps the count. Every opacity_reset_interval steps the
// opacities are lowered to at most 0.01.
//
// Deterministic for a seed on the CPU: views are visited in a seeded random order, splits draw
// from a seeded generator, and the rasterizer's gradients do not depend on the thread schedule.
// On a CUDA device (`device`) the gradients' sums depend on the GPU's schedule (float rounding).

#include <cstdint>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/neural/gaussian_cloud.hpp"
#include "hanzo/fusion/neural/splat_rasterizer.hpp"
#include "hanzo/fusion/neural/splat_rasterizer_cuda.hpp"
#include "hanzo/fusion/neural/view_dataset.hpp"

namespace hanzo::fusion::neural {

struct SplatTrainingConfig {
  int iterations = 6000;          ///< steps (one view each)
  int sh_degree = 3;              ///< degree of the colour's spherical harmonics (0..3)
  int sh_degree_interval = 1000;  ///< steps between raising the active degree
  double position_lr_initial = 1.6e-4;  ///< x scene extent
  double position_lr_final = 1.6e-6;    ///< x scene extent
  double sh_dc_lr = 2.5e-3;
  double sh_rest_lr = 2.5e-3 / 20.0;
  double opacity_lr = 0.025;
  double scale_lr = 5e-3;
  double rotation_lr = 1e-3;
  double ssim_weight = 0.2;
  // The reference's schedule (30,000 steps: densify from 500 to 15,000, reset every 3,000) in
  // shares of the run, so that a short run still densifies, resets and prunes.
  int densify_from = 0;            ///< 0: the smaller of 500 and a tenth of the iterations
  int densify_until = 0;           ///< 0: half the iterations
  int densify_interval = 100;
  int opacity_reset_interval = 0;  ///< 0: a tenth of the iterations, at least 1000
  double max_screen_share = 0.025;  ///< after the first reset, Gaussians wider than this share of the image are removed
  double densify_gradient_threshold = 2e-4;
  double dense_percent = 0.01;
  double min_opacity = 0.005;
  int max_gaussians = 500000;
  int initial_gaussians = 50000;  ///< random initialization when there are no points
  uint64_t seed = 1;
  RasterizerConfig rasterizer;    ///< background and near plane (the active degree is the trainer's)
  /// Where renders and gradients run: the CPU (default, deterministic), a CUDA device (creation
  /// fails without one), or auto (CUDA when present). A device error during training moves the
  /// rest of the run to the CPU (logged).
  SplatDevice device = SplatDevice::kCpu;
};

Status validate(const SplatTrainingConfig& config);

/// Gaussians spread uniformly in the cube of half-size `half_size` around `centre`, grey, opacity
/// 0.1, isotropic with about the spacing of their neighbours. With views that carry masks
/// (RGBA), only points inside every view's foreground that sees them are kept (the visual hull).
GaussianCloud initialize_gaussians(const std::vector<PosedView>& views, const Eigen::Vector3d& centre, double half_size, int count, int sh_degree,
                                   uint64_t seed);

/// Gaussians at a map's points (world frame, the views' frame: a session's map), at most `count`
/// of them (an even, seeded selection), each coloured by the first view that sees it in front of
/// its camera, opacity 0.1, isotropic with the mean distance to its three nearest selected
/// neighbours (Kerbl et al. Sec. 5.1); points no view sees are left out.
GaussianCloud initialize_gaussians_at_points(const std::vector<PosedView>& views, const std::vector<Eigen::Vector3f>& points, int count, int sh_degree,
                                            uint64_t seed);

class SplatTrainer {
 public:
  /// `scene_extent`: the scene's size for the learning rates and densification (scene units).
  static Result<SplatTrainer> create(GaussianCloud initial, double scene_extent, SplatTrainingConfig config);

  /// One step on `view` (its image and camera). Returns the loss.
  double step(const PosedView& view);
  /// Appends Gaussians (a scene that grows as a session's views arrive), their optimizer state
  /// and densification statistics zero, at most up to max_gaussians (the first ones of `more`).
  /// Fails for another degree or inconsistent arrays; nothing changes then.
  Status add_gaussians(const GaussianCloud& more);
  /// Changes the cap of densification and add_gaussians (a growing scene's budget); Gaussians
  /// beyond it stay.
  void set_max_gaussians(int max_gaussians) { config_.max_gaussians = max_gaussians; }

  const GaussianCloud& cloud() const { return cloud_; }
  int iteration() const { return iteration_; }
  const SplatTrainingConfig& config() const { return config_; }
  RasterizerConfig render_config() const;  ///< the rasterizer settings at the current step
  /// "cpu" or the CUDA device's name (where the steps run now).
  std::string device_name() const;

 private:
  SplatTrainer() = default;
  void densify_and_prune();
  void reset_opacity();
  void apply_keep(const std::vector<bool>& keep);
  void append_gaussians(const std::vector<std::size_t>& sources, bool split);
  /// Zero Adam moments for Gaussians appended since (the arrays' new sizes).
  void grow_optimizer_state();
  /// The loss (paper eq. 7) of a render against the view's image; dL/dimage into `loss_gradient`.
  double loss_of(const SplatRender& render, const PosedView& view, std::vector<float>& loss_gradient) const;
  /// Renders, takes the loss and back-propagates into gradients_ on the CUDA device; false (and
  /// the CPU from now on) on a device error.
  bool gpu_pass(const PosedView& view, const RasterizerConfig& rasterizer, SplatRender& render, double& loss);

  GaussianCloud cloud_;
  double extent_ = 1.0;
  SplatTrainingConfig config_;
  int iteration_ = 0;
  GaussianGradients gradients_;
  std::vector<std::vector<float>> adam_m_, adam_v_;  // per parameter group
  std::vector<float> densify_gradient_sum_;
  std::vector<int> densify_count_;
  std::vector<float> max_screen_share_;  // largest drawn radius / image size since the last densification
  std::mt19937_64 random_;
  std::shared_ptr<CudaSplatRasterizer> gpu_;  // null: the CPU
};

/// Renders every view that has an image and scores it (PSNR, SSIM).
EvaluationSummary evaluate_splats(const GaussianCloud& cloud, const std::vector<PosedView>& views, const RasterizerConfig& config);

}  // namespace hanzo::fusion::neural
