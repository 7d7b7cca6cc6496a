#pragma once
// NerfTrainer: fits a NerfField to posed images (instant-ngp's training, Mueller et al. 2022,
// Sec. 5.4 and Appendix E).
//
// Each step draws random pixels of random training views (a uniform offset inside the pixel),
// marches their rays through the occupancy grid from a random offset inside the first step,
// keeps as many rays as fit samples_per_step, renders them (volume_rendering.hpp) and takes the
// mean squared error against the pixels; the gradients run back through the compositing, the
// networks and the hash encoding (volume_rendering.hpp, mlp.hpp, hash_encoding.hpp), and Adam
// (beta 0.9 / 0.99, epsilon 1e-15) moves every parameter; entries without a gradient in the step
// keep their value and moments. The learning rate is `learning_rate` for
// the first half of the run and decays exponentially to final_learning_rate at its end.
// For views with an alpha mask (RGBA), each ray's background is a random colour and the target
// the pixel re-composited on it, so that empty space must learn zero density (instead of
// painting the background onto it).
// The occupancy grid is refreshed every occupancy_interval steps: every cell during the first
// occupancy_warmup steps, later a share of random and of occupied cells. Cells that no training
// camera sees stay empty.
//
// Deterministic for a seed, whatever the thread count (every sum runs in a fixed order).

#include <cstdint>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/neural/nerf_field.hpp"
#include "hanzo/fusion/neural/view_dataset.hpp"
#include "hanzo/fusion/neural/volume_rendering.hpp"

namespace hanzo::fusion::neural {

struct NerfTrainingConfig {
  int iterations = 5000;
  int samples_per_step = 1 << 17;  ///< samples (network evaluations) per step
  int max_samples_per_ray = 1024;
  double learning_rate = 1e-2;
  double final_learning_rate = 1e-3;
  double adam_beta1 = 0.9, adam_beta2 = 0.99, adam_epsilon = 1e-15;
  int occupancy_interval = 16;
  int occupancy_warmup = 64;  ///< steps during which every cell is refreshed
  double occupancy_share = 1.0 / 16.0;  ///< of the cells drawn at random per refresh (and as many occupied ones)
  Eigen::Vector3f image_background = Eigen::Vector3f::Ones();  ///< what RGBA views were composited on when read
  bool random_background = true;   ///< for views with masks
  uint64_t seed = 1;
};

Status validate(const NerfTrainingConfig& config);

/// The box for a dataset: the reader's box when it has one (sensor logs), else transforms'
/// aabb_scale when given (instant-ngp's convention: a cube of half size 1.5 x aabb_scale around
/// the origin of the file's frame), else a cube of 0.375 of the cameras' mean distance around the
/// point their axes pass nearest.
void set_scene_box(const ViewDataset& dataset, NerfFieldConfig& config);

class NerfTrainer {
 public:
  /// `views` (with images) must outlive the trainer.
  static Result<NerfTrainer> create(NerfField field, const std::vector<PosedView>& views, const NerfTrainingConfig& config);
  NerfTrainer(NerfTrainer&&) noexcept;
  NerfTrainer& operator=(NerfTrainer&&) noexcept;
  ~NerfTrainer();

  /// One step. Returns the mean squared error of the step's rays.
  double step();

  const NerfField& field() const { return field_; }
  NerfField&& release_field() { return std::move(field_); }
  int iteration() const { return iteration_; }
  double samples_per_ray() const { return samples_per_ray_; }  ///< running mean
  int rays_per_step() const { return rays_; }

 private:
  explicit NerfTrainer(NerfField field) : field_(std::move(field)) {}
  /// The step's rays: their samples, directions, target colours and backgrounds.
  struct RayBatch {
    RaySamples samples;
    std::vector<Eigen::Vector3f> directions;
    std::vector<float> target, background;  // 3 per ray
  };
  void draw_rays(RayBatch& batch);
  void mark_seen_cells();
  void update_occupancy();
  void adam_step(double learning_rate);

  NerfField field_;
  const std::vector<PosedView>* views_ = nullptr;
  NerfTrainingConfig config_;
  int iteration_ = 0;
  int rays_ = 4096;
  double samples_per_ray_ = 0.0;
  std::vector<std::vector<float>> adam_m_, adam_v_, gradients_;  // per parameter group
  std::mt19937_64 random_;
};

/// Renders every view that has an image on `background` and scores it (PSNR, SSIM).
EvaluationSummary evaluate_nerf(const NerfField& field, const std::vector<PosedView>& views, const Eigen::Vector3f& background);

}  // namespace hanzo::fusion::neural
