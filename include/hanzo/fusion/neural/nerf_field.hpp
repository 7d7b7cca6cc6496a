#pragma once
// A neural radiance field in the instant-ngp layout (Mueller et al., SIGGRAPH 2022, Sec. 5.4):
// the multiresolution hash encoding of the position (hash_encoding.hpp) into a density network
// (one hidden layer of `hidden_width` ReLU units, 16 outputs: the first is the log density, the
// others feed the colour), and a colour network (two hidden layers) on those 15 features plus the
// view direction's spherical harmonics up to degree 3 (16 values), ending in a sigmoid; no
// biases, as in tiny-cuda-nn. Density = exp(log density) (clamped to exp(+-15)), colour the
// sigmoid of the colour network's outputs.
//
// The scene box (centre, half size in scene units) maps onto the unit cube that the encoding and
// the occupancy grid (occupancy_grid.hpp) cover; rays are marched at a fixed step of
// sqrt(3) / steps_per_diagonal of the cube. Rendering (render_nerf) marches each pixel's ray in
// rounds over the occupied cells, evaluates the network on the new samples, composites them
// (volume_rendering.hpp) and drops the rays whose transmittance fell under 1e-4.
//
// Everything runs on the CPU in this project's kernels (TBB): the encoding, the networks
// (mlp.hpp), the marching and the compositing. Files (save_nerf / load_nerf): "HZNERF1\n", the configuration and shapes as
// one JSON line, then the parameters as little-endian float32 and the occupancy grid.

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/neural/hash_encoding.hpp"
#include "hanzo/fusion/neural/occupancy_grid.hpp"
#include "hanzo/fusion/neural/splat_rasterizer.hpp"

namespace hanzo::fusion::neural {

struct NerfFieldConfig {
  HashGridConfig encoding;
  OccupancyGridConfig occupancy;
  int hidden_width = 64;              ///< units of every hidden layer
  int steps_per_diagonal = 1024;      ///< marching step = sqrt(3) / this, in unit-cube lengths
  Eigen::Vector3d box_centre = Eigen::Vector3d::Zero();  ///< scene units
  double box_half_size = 1.5;         ///< scene units
  double near = 0.2;                  ///< rays start this far from the camera at least (scene units)
  uint64_t seed = 1;                  ///< initial weights
};

Status validate(const NerfFieldConfig& config);

/// Colour (RGB 0..1), depth (scene units along the ray divided by the opacity; 0 where empty)
/// and opacity per pixel.
struct NerfRender {
  int width = 0, height = 0;
  std::vector<float> image, depth, opacity;
};

class NerfField {
 public:
  static Result<NerfField> create(const NerfFieldConfig& config);
  NerfField(NerfField&&) noexcept;
  NerfField& operator=(NerfField&&) noexcept;
  ~NerfField();

  const NerfFieldConfig& config() const;
  const HashGrid& encoding() const;
  OccupancyGrid& occupancy();
  const OccupancyGrid& occupancy() const;
  float step() const;  ///< marching step (unit-cube lengths)
  std::size_t parameter_count() const;

  /// Scene point to unit-cube coordinates and back (uniform scale 1 / (2 half size)).
  Eigen::Vector3f to_unit(const Eigen::Vector3d& point_scene) const;
  double unit_to_scene_length() const { return 2.0 * config().box_half_size; }
  /// Where the ray from `origin` (unit cube) along `direction` is marched: from the cube's entry
  /// or the near distance, whichever is later, to its exit (false: it misses the cube).
  bool ray_span(const Eigen::Vector3f& origin, const Eigen::Vector3f& direction, float& t_begin, float& t_end) const;

  /// Densities (per unit-cube length) at unit-cube points, without gradients.
  void density(const float* positions, std::size_t count, float* density) const;

  /// Renders the camera's view on `background`.
  NerfRender render(const SplatCamera& camera, const Eigen::Vector3f& background, std::size_t rays_per_batch = 1 << 14) const;

  struct Network;  // the encoding, the networks and their parameters (nerf_network.hpp)
  Network& network();
  const Network& network() const;

 private:
  NerfField();
  std::unique_ptr<Network> network_;
};

/// The model file ("HZNERF1\n", a JSON header line, the parameter groups and the occupancy grid:
/// src/neural/nerf_file.cpp) and its bytes; parse_nerf refuses a wrong header, sizes that
/// disagree with the configuration and truncated data, prefixing errors with `source`.
std::string serialize_nerf(const NerfField& field);
Result<NerfField> parse_nerf(std::string_view bytes, const std::string& source);
Status save_nerf(const std::string& path, const NerfField& field);
Result<NerfField> load_nerf(const std::string& path);

}  // namespace hanzo::fusion::neural
