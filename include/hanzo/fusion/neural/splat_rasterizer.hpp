#pragma once
// The tile-based differentiable rasterizer of 3D Gaussian splatting (Kerbl et al., SIGGRAPH 2023,
// Sec. 6), forward and backward, multi-threaded on the CPU (TBB over 16 x 16 pixel tiles).
//
// Forward, per Gaussian: the mean in the camera's optical frame (x right, y down, z forward),
// skipped at z < near; its 2D covariance Sigma' = J W Sigma W^T J^T (paper eq. 5, EWA splatting
// with the affine approximation J of the pinhole projection at the mean) plus
// `low_pass` pixels^2 on the diagonal; its extent 3 sqrt(largest eigenvalue) in pixels and the
// tiles that extent touches; its colour from the spherical harmonics along the viewing direction.
// Per tile, the Gaussians sorted front to back by depth; per pixel (centre at integer
// coordinates: the camera's principal point is in OpenCV's convention),
//   alpha_i = min(0.99, o_i exp(-0.5 d^T Sigma'^-1 d)), d = pixel - mean_2d
//   C = sum_i c_i alpha_i T_i + T_final background,  T_i = prod_{j<i} (1 - alpha_j)
// (paper eq. 3), skipping alpha < 1/255 and stopping once T < 1e-4. Depth is the same blend of
// the Gaussians' z (divided by the accumulated alpha where `normalize_depth`).
//
// Backward: the gradients of a loss from dL/dC per pixel to every Gaussian parameter, walking
// each pixel's contributors back to front (the paper's Sec. 6), then through the 2D covariance,
// the projection, the covariance's scale and rotation and the spherical harmonics. Each
// (tile, Gaussian) pair accumulates into its own slot and the slots are summed in a fixed order,
// so that the gradients do not depend on the thread schedule.
//
// Failures: none at run time; a Gaussian behind the camera or covering no pixel takes no part
// and gets zero gradient.

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/neural/gaussian_cloud.hpp"

namespace hanzo::fusion::neural {

/// A pinhole camera without distortion; T_camera_world maps world points into the optical frame.
struct SplatCamera {
  int width = 0, height = 0;  ///< pixels
  double fx = 0.0, fy = 0.0, cx = 0.0, cy = 0.0;  ///< pixels; pixel centres at integer coordinates
  Eigen::Matrix3d R_camera_world = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_camera_world = Eigen::Vector3d::Zero();
  Eigen::Vector3d centre_world() const { return -R_camera_world.transpose() * t_camera_world; }
};

struct RasterizerConfig {
  Eigen::Vector3f background = Eigen::Vector3f::Ones();  ///< colour behind every Gaussian (0..1)
  double near = 0.2;           ///< Gaussians closer than this (scene units along z) are skipped, as the reference does
  double low_pass = 0.3;       ///< pixels^2 added to the 2D covariance's diagonal (anti-aliasing)
  int active_sh_degree = 3;    ///< SH degree used (<= the cloud's): the trainer raises it over time
  bool normalize_depth = true;  ///< depth divided by the accumulated alpha
};

/// What the forward pass keeps for the backward pass and the caller.
struct SplatRender {
  int width = 0, height = 0;
  std::vector<float> image;  ///< RGB, row-major, 3 floats a pixel
  std::vector<float> depth;  ///< z per pixel (0 where nothing was drawn)
  std::vector<float> alpha;  ///< 1 - T_final per pixel

  // Per-Gaussian projection (size of the cloud; radius 0: not drawn).
  std::vector<Eigen::Vector2f> mean_2d;
  std::vector<Eigen::Vector3f> conic;  ///< Sigma'^-1 as (a, b, c): [[a, b], [b, c]]
  std::vector<Eigen::Vector3f> colour;
  std::vector<float> view_depth;
  std::vector<int> radius;             ///< the box's larger half-width, rounded up (0: not drawn)
  std::vector<Eigen::Vector2f> extent;  ///< the box's half-widths (pixels)
  std::vector<float> opacity;           ///< sigmoid(opacity_logit)
  std::vector<uint8_t> colour_clamped;  ///< per channel bit: the colour was clamped at 0
  // Tiles: Gaussian indices sorted by tile, then depth; tile t owns [tile_range[t], tile_range[t+1]).
  int tiles_x = 0, tiles_y = 0;
  std::vector<uint32_t> tile_range;
  std::vector<uint32_t> tile_gaussians;
  std::vector<float> final_transmittance;  ///< T_final per pixel
  std::vector<uint32_t> contributors;      ///< per pixel: how many of its tile's list were walked

  int drawn() const;  ///< Gaussians with a radius
};

inline constexpr int kTileSize = 16;

/// Renders the cloud from the camera.
SplatRender render_splats(const GaussianCloud& cloud, const SplatCamera& camera, const RasterizerConfig& config = {});

/// Adds to `gradients` (sized like the cloud) dL/dparameters for dL/dimage (RGB per pixel, the
/// forward's layout); also adds |dL/dmean_2d| (in normalized device coordinates: pixels x 2 /
/// the image's size) to screen_gradient_norm and counts the view in
/// visible_views for every drawn Gaussian.
void render_splats_backward(const GaussianCloud& cloud, const SplatCamera& camera, const RasterizerConfig& config, const SplatRender& forward,
                            const std::vector<float>& loss_gradient_image, GaussianGradients& gradients);

}  // namespace hanzo::fusion::neural
