#include "hanzo/fusion/neural/splat_rasterizer.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <tbb/parallel_for.h>

#include "splat_kernels.hpp"

namespace hanzo::fusion::neural {

namespace {

using kernels::TileSplat;
static_assert(kernels::kTileSize == kTileSize);

int active_degree(const GaussianCloud& cloud, const RasterizerConfig& config) { return std::clamp(config.active_sh_degree, 0, cloud.sh_degree); }

void gather_tile(const SplatRender& render, uint32_t begin, uint32_t end, std::vector<TileSplat>& splats) {
  splats.clear();
  for (uint32_t k = begin; k < end; ++k) {
    const uint32_t g = render.tile_gaussians[k];
    splats.push_back(kernels::make_tile_splat(render.mean_2d[g].data(), render.extent[g].data(), render.conic[g].data(), render.opacity[g],
                                              render.colour[g].data(), render.view_depth[g]));
  }
}

// The tile's splats whose box spans pixel row y, in depth order.
void gather_row(const std::vector<TileSplat>& splats, float y, std::vector<uint32_t>& row) {
  row.clear();
  for (std::size_t j = 0; j < splats.size(); ++j) {
    if (splats[j].y0 <= y && y <= splats[j].y1) row.push_back(static_cast<uint32_t>(j));
  }
}

}  // namespace

kernels::CameraParams camera_params(const SplatCamera& camera) {
  kernels::CameraParams params{};
  const Eigen::Matrix3f rotation = camera.R_camera_world.cast<float>();
  const Eigen::Vector3f centre = camera.centre_world().cast<float>();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) params.R[3 * r + c] = rotation(r, c);
    params.t[r] = static_cast<float>(camera.t_camera_world[r]);
    params.centre[r] = centre[r];
  }
  params.fx = static_cast<float>(camera.fx);
  params.fy = static_cast<float>(camera.fy);
  params.cx = static_cast<float>(camera.cx);
  params.cy = static_cast<float>(camera.cy);
  params.limit_x = kernels::kFrustumMargin * 0.5f * static_cast<float>(camera.width) / params.fx;
  params.limit_y = kernels::kFrustumMargin * 0.5f * static_cast<float>(camera.height) / params.fy;
  params.width = camera.width;
  params.height = camera.height;
  params.tiles_x = (camera.width + kTileSize - 1) / kTileSize;
  params.tiles_y = (camera.height + kTileSize - 1) / kTileSize;
  return params;
}

namespace {

// Runs visit(first list index of the tile, its splats, the row's splats, x, y, pixel index) for
// every pixel, the tiles in parallel; both passes walk the same splats in the same order.
template <typename Visit>
void for_each_tile_pixel(const SplatRender& render, Visit&& visit) {
  tbb::parallel_for(0, render.tiles_x * render.tiles_y, [&](int tile) {
    const int tile_x = tile % render.tiles_x, tile_y = tile / render.tiles_x;
    const uint32_t begin = render.tile_range[static_cast<std::size_t>(tile)], end = render.tile_range[static_cast<std::size_t>(tile) + 1];
    thread_local std::vector<TileSplat> splats;
    thread_local std::vector<uint32_t> row;
    gather_tile(render, begin, end, splats);
    for (int y = tile_y * kTileSize; y < std::min(render.height, (tile_y + 1) * kTileSize); ++y) {
      gather_row(splats, static_cast<float>(y), row);
      for (int x = tile_x * kTileSize; x < std::min(render.width, (tile_x + 1) * kTileSize); ++x) {
        visit(begin, splats, row, x, y, static_cast<std::size_t>(y) * static_cast<std::size_t>(render.width) + static_cast<std::size_t>(x));
      }
    }
  });
}

}  // namespace

int SplatRender::drawn() const {
  return static_cast<int>(std::count_if(radius.begin(), radius.end(), [](int r) { return r > 0; }));
}

SplatRender render_splats(const GaussianCloud& cloud, const SplatCamera& camera_in, const RasterizerConfig& config) {
  const kernels::CameraParams camera = camera_params(camera_in);
  const auto n = static_cast<int>(cloud.size());
  const int degree = active_degree(cloud, config);
  const int sh_floats = cloud.sh_floats();
  SplatRender out;
  out.width = camera_in.width;
  out.height = camera_in.height;
  out.tiles_x = camera.tiles_x;
  out.tiles_y = camera.tiles_y;
  out.mean_2d.assign(static_cast<std::size_t>(n), Eigen::Vector2f::Zero());
  out.conic.assign(static_cast<std::size_t>(n), Eigen::Vector3f::Zero());
  out.colour.assign(static_cast<std::size_t>(n), Eigen::Vector3f::Zero());
  out.view_depth.assign(static_cast<std::size_t>(n), 0.0f);
  out.radius.assign(static_cast<std::size_t>(n), 0);
  out.extent.assign(static_cast<std::size_t>(n), Eigen::Vector2f::Zero());
  out.opacity.assign(static_cast<std::size_t>(n), 0.0f);
  out.colour_clamped.assign(static_cast<std::size_t>(n), 0);
  std::vector<Eigen::Vector4i> rects(static_cast<std::size_t>(n));  // tile x0, y0, x1, y1 (exclusive)

  // 1. Project every Gaussian.
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 1024), [&](const tbb::blocked_range<int>& range) {
    for (int i = range.begin(); i != range.end(); ++i) {
      const auto index = static_cast<std::size_t>(i);
      kernels::Projection projection;
      if (!kernels::project_gaussian(&cloud.position[3 * index], &cloud.log_scale[3 * index], &cloud.rotation[4 * index], cloud.opacity_logit[index],
                                     &cloud.sh[index * static_cast<std::size_t>(sh_floats)], degree, camera, static_cast<float>(config.near),
                                     static_cast<float>(config.low_pass), projection)) {
        continue;
      }
      out.mean_2d[index] = Eigen::Vector2f(projection.mean[0], projection.mean[1]);
      out.conic[index] = Eigen::Vector3f(projection.conic[0], projection.conic[1], projection.conic[2]);
      out.colour[index] = Eigen::Vector3f(projection.colour[0], projection.colour[1], projection.colour[2]);
      out.colour_clamped[index] = static_cast<uint8_t>(projection.clamped);
      out.view_depth[index] = projection.depth;
      out.radius[index] = projection.radius;
      out.extent[index] = Eigen::Vector2f(projection.extent[0], projection.extent[1]);
      out.opacity[index] = projection.opacity;
      rects[index] = Eigen::Vector4i(projection.rect[0], projection.rect[1], projection.rect[2], projection.rect[3]);
    }
  });

  // 2. Per tile, its Gaussians front to back (ties by index: the same order on every run).
  const int tile_count = out.tiles_x * out.tiles_y;
  std::vector<uint32_t> counts(static_cast<std::size_t>(tile_count) + 1, 0);
  for (int i = 0; i < n; ++i) {
    if (out.radius[static_cast<std::size_t>(i)] == 0) continue;
    const Eigen::Vector4i& rect = rects[static_cast<std::size_t>(i)];
    for (int ty = rect[1]; ty < rect[3]; ++ty) {
      for (int tx = rect[0]; tx < rect[2]; ++tx) ++counts[static_cast<std::size_t>(ty * out.tiles_x + tx) + 1];
    }
  }
  std::partial_sum(counts.begin(), counts.end(), counts.begin());
  out.tile_range = counts;
  out.tile_gaussians.resize(counts.back());
  std::vector<uint32_t> fill(counts.begin(), counts.end() - 1);
  for (int i = 0; i < n; ++i) {
    if (out.radius[static_cast<std::size_t>(i)] == 0) continue;
    const Eigen::Vector4i& rect = rects[static_cast<std::size_t>(i)];
    for (int ty = rect[1]; ty < rect[3]; ++ty) {
      for (int tx = rect[0]; tx < rect[2]; ++tx) out.tile_gaussians[fill[static_cast<std::size_t>(ty * out.tiles_x + tx)]++] = static_cast<uint32_t>(i);
    }
  }
  tbb::parallel_for(0, tile_count, [&](int tile) {
    auto first = out.tile_gaussians.begin() + out.tile_range[static_cast<std::size_t>(tile)];
    auto last = out.tile_gaussians.begin() + out.tile_range[static_cast<std::size_t>(tile) + 1];
    std::sort(first, last, [&](uint32_t a, uint32_t b) { return out.view_depth[a] < out.view_depth[b] || (out.view_depth[a] == out.view_depth[b] && a < b); });
  });

  // 3. Blend per pixel.
  const auto pixels = static_cast<std::size_t>(out.width) * static_cast<std::size_t>(out.height);
  out.image.assign(3 * pixels, 0.0f);
  out.depth.assign(pixels, 0.0f);
  out.alpha.assign(pixels, 0.0f);
  out.final_transmittance.assign(pixels, 1.0f);
  out.contributors.assign(pixels, 0);
  for_each_tile_pixel(out, [&](uint32_t, const std::vector<TileSplat>& splats, const std::vector<uint32_t>& row, int x, int y, std::size_t pixel) {
    float transmittance = 1.0f, depth = 0.0f;
    Eigen::Vector3f colour = Eigen::Vector3f::Zero();
    uint32_t walked = 0;
    for (const uint32_t j : row) {
      float dx = 0.0f, dy = 0.0f, gaussian = 0.0f, alpha = 0.0f;
      if (!kernels::evaluate_splat(splats[j], static_cast<float>(x), static_cast<float>(y), dx, dy, gaussian, alpha)) continue;
      const float next = transmittance * (1.0f - alpha);
      if (next < kernels::kMinTransmittance) break;
      colour += Eigen::Map<const Eigen::Vector3f>(splats[j].colour) * (alpha * transmittance);
      depth += splats[j].depth * alpha * transmittance;
      transmittance = next;
      walked = j + 1;
    }
    const Eigen::Vector3f final_colour = colour + transmittance * config.background;
    std::copy(final_colour.data(), final_colour.data() + 3, &out.image[3 * pixel]);
    out.alpha[pixel] = 1.0f - transmittance;
    out.depth[pixel] = config.normalize_depth && out.alpha[pixel] > 1e-6f ? depth / out.alpha[pixel] : depth;
    out.final_transmittance[pixel] = transmittance;
    out.contributors[pixel] = walked;
  });
  return out;
}

void render_splats_backward(const GaussianCloud& cloud, const SplatCamera& camera_in, const RasterizerConfig& config, const SplatRender& forward,
                            const std::vector<float>& loss_gradient_image, GaussianGradients& gradients) {
  constexpr int kPair = kernels::kPairGradients;
  const kernels::CameraParams camera = camera_params(camera_in);
  const auto n = static_cast<int>(cloud.size());
  const int degree = active_degree(cloud, config);
  const int sh_floats = cloud.sh_floats();
  std::vector<float> slots(forward.tile_gaussians.size() * kPair, 0.0f);

  // 1. Per pixel, back to front: dL/d(2D mean, conic, colour, opacity) into the pair's slot.
  for_each_tile_pixel(forward, [&](uint32_t begin, const std::vector<TileSplat>& splats, const std::vector<uint32_t>& row, int x, int y, std::size_t pixel) {
    kernels::PixelBackward walk(&loss_gradient_image[3 * pixel], forward.final_transmittance[pixel], config.background.data());
    // The row's splats before the last contributor, back to front.
    const auto last = std::lower_bound(row.begin(), row.end(), forward.contributors[pixel]);
    for (auto it = last; it != row.begin();) {
      const uint32_t j = *--it;
      float dx = 0.0f, dy = 0.0f, gaussian = 0.0f, alpha = 0.0f;
      if (!kernels::evaluate_splat(splats[j], static_cast<float>(x), static_cast<float>(y), dx, dy, gaussian, alpha)) continue;
      float pair[kPair];
      walk.step(splats[j], dx, dy, gaussian, alpha, pair);
      float* slot = &slots[static_cast<std::size_t>(begin + j) * kPair];
      for (int k = 0; k < kPair; ++k) slot[k] += pair[k];
    }
  });

  // 2. The pairs summed per Gaussian in list order (deterministic).
  std::vector<float> per_gaussian(static_cast<std::size_t>(n) * kPair, 0.0f);
  for (std::size_t k = 0; k < forward.tile_gaussians.size(); ++k) {
    float* sum = &per_gaussian[static_cast<std::size_t>(forward.tile_gaussians[k]) * kPair];
    const float* slot = &slots[k * kPair];
    for (int j = 0; j < kPair; ++j) sum[j] += slot[j];
  }

  // 3. Per Gaussian: through the projection, the 2D covariance, scale, rotation and colour.
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 1024), [&](const tbb::blocked_range<int>& range) {
    for (int i = range.begin(); i != range.end(); ++i) {
      const auto index = static_cast<std::size_t>(i);
      if (forward.radius[index] == 0) continue;
      kernels::Projection projection{};
      std::copy(forward.conic[index].data(), forward.conic[index].data() + 3, projection.conic);
      projection.opacity = forward.opacity[index];
      projection.clamped = forward.colour_clamped[index];
      const kernels::GaussianGradientOut out{&gradients.position[3 * index], &gradients.log_scale[3 * index], &gradients.rotation[4 * index],
                                             &gradients.opacity_logit[index], &gradients.sh[index * static_cast<std::size_t>(sh_floats)]};
      gradients.screen_gradient_norm[index] +=
          kernels::gaussian_backward(&cloud.position[3 * index], &cloud.log_scale[3 * index], &cloud.rotation[4 * index],
                                     &cloud.sh[index * static_cast<std::size_t>(sh_floats)], degree, camera, projection, &per_gaussian[index * kPair], out);
      gradients.visible_views[index] += 1;
    }
  });
}

}  // namespace hanzo::fusion::neural
