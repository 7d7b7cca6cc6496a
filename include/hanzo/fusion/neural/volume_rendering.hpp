#pragma once
// Emission-absorption volume rendering along rays (Max 1995; NeRF, Mildenhall et al., ECCV 2020,
// eq. 3), forward and backward, over samples stored ray after ray.
//
// For the samples i of one ray (in order of distance), with density sigma_i (per unit of t),
// length dt_i and colour c_i:
//   alpha_i = 1 - exp(-sigma_i dt_i),  T_i = prod_{j<i} (1 - alpha_j),  w_i = T_i alpha_i
//   C = sum_i w_i c_i + T_final background,  depth = sum_i w_i t_i,  opacity = 1 - T_final.
// The gradients, with S_i = C - sum_{k<=i} w_k c_k (what the samples behind i and the background add):
//   dC/dc_i = w_i,  dC/dsigma_i = dt_i (T_{i+1} c_i - S_i).
// A ray stops early when T falls under min_transmittance (the later samples get no weight and
// zero gradient).

#include <cstddef>
#include <cstdint>
#include <vector>

namespace hanzo::fusion::neural {

/// Samples along rays: ray r owns samples [ray_begin[r], ray_begin[r + 1]).
struct RaySamples {
  std::vector<uint32_t> ray_begin{0};
  std::vector<float> t, dt;        ///< per sample: distance along the ray and the length it stands for
  std::vector<float> position;     ///< per sample: x, y, z
  std::size_t rays() const { return ray_begin.size() - 1; }
  std::size_t size() const { return t.size(); }
  void clear() {
    ray_begin.assign(1, 0);
    t.clear();
    dt.clear();
    position.clear();
  }
};

struct CompositeResult {
  std::vector<float> colour;   ///< 3 per ray
  std::vector<float> depth;    ///< per ray: sum w_i t_i (not divided by the opacity)
  std::vector<float> opacity;  ///< per ray: 1 - T_final
};

/// `background`: 3 per ray.
CompositeResult composite(const RaySamples& samples, const float* density, const float* colour, const float* background,
                          float min_transmittance = 1e-4f);

/// dL/d density and dL/d colour (3 per sample) from dL/d colour per ray; `result` is composite()'s.
/// (The background enters through result.colour.)
void composite_backward(const RaySamples& samples, const float* density, const float* colour, const CompositeResult& result, const float* colour_gradient,
                        float* density_gradient, float* sample_colour_gradient, float min_transmittance = 1e-4f);

}  // namespace hanzo::fusion::neural
