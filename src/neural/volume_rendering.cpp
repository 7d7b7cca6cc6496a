#include "hanzo/fusion/neural/volume_rendering.hpp"

#include <cmath>

#include <tbb/parallel_for.h>

namespace hanzo::fusion::neural {

CompositeResult composite(const RaySamples& samples, const float* density, const float* colour, const float* background, float min_transmittance) {
  const std::size_t rays = samples.rays();
  CompositeResult result;
  result.colour.assign(3 * rays, 0.0f);
  result.depth.assign(rays, 0.0f);
  result.opacity.assign(rays, 0.0f);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays, 256), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t r = range.begin(); r != range.end(); ++r) {
      float transmittance = 1.0f;
      float c[3] = {0.0f, 0.0f, 0.0f};
      float depth = 0.0f;
      for (uint32_t i = samples.ray_begin[r]; i < samples.ray_begin[r + 1]; ++i) {
        if (transmittance < min_transmittance) break;
        const float alpha = 1.0f - std::exp(-density[i] * samples.dt[i]);
        const float weight = transmittance * alpha;
        for (int k = 0; k < 3; ++k) c[k] += weight * colour[3 * i + k];
        depth += weight * samples.t[i];
        transmittance *= 1.0f - alpha;
      }
      for (int k = 0; k < 3; ++k) result.colour[3 * r + k] = c[k] + transmittance * background[3 * r + k];
      result.depth[r] = depth;
      result.opacity[r] = 1.0f - transmittance;
    }
  });
  return result;
}

void composite_backward(const RaySamples& samples, const float* density, const float* colour, const CompositeResult& result, const float* colour_gradient,
                        float* density_gradient, float* sample_colour_gradient, float min_transmittance) {
  const std::size_t rays = samples.rays();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, rays, 256), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t r = range.begin(); r != range.end(); ++r) {
      const float* g = colour_gradient + 3 * r;
      // S starts as the whole colour and loses each sample's contribution as the walk passes it.
      float rest[3] = {result.colour[3 * r], result.colour[3 * r + 1], result.colour[3 * r + 2]};
      float transmittance = 1.0f;
      bool stopped = false;
      for (uint32_t i = samples.ray_begin[r]; i < samples.ray_begin[r + 1]; ++i) {
        if (stopped || transmittance < min_transmittance) {
          stopped = true;
          density_gradient[i] = 0.0f;
          for (int k = 0; k < 3; ++k) sample_colour_gradient[3 * i + k] = 0.0f;
          continue;
        }
        const float alpha = 1.0f - std::exp(-density[i] * samples.dt[i]);
        const float weight = transmittance * alpha;
        const float after = transmittance * (1.0f - alpha);  // T_{i+1}
        float d_density = 0.0f;
        for (int k = 0; k < 3; ++k) {
          rest[k] -= weight * colour[3 * i + k];
          sample_colour_gradient[3 * i + k] = weight * g[k];
          d_density += g[k] * (after * colour[3 * i + k] - rest[k]);
        }
        density_gradient[i] = samples.dt[i] * d_density;
        transmittance = after;
      }
    }
  });
}

}  // namespace hanzo::fusion::neural
