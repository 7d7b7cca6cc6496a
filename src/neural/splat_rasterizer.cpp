#include "hanzo/fusion/neural/splat_rasterizer.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <ceres/jet.h>
#include <tbb/parallel_for.h>

#include "spherical_harmonics.hpp"

namespace hanzo::fusion::neural {

namespace {

constexpr float kMinAlpha = 1.0f / 255.0f;
constexpr float kMaxAlpha = 0.99f;
constexpr float kMinTransmittance = 1e-4f;
// |x/z| and |y/z| are clamped to this multiple of the half field of view in the Jacobian (as the
// reference implementation does): Gaussians far outside the view get a bounded footprint.
constexpr float kFrustumMargin = 1.3f;

Eigen::Matrix3f rotation_of(const float* q_raw, Eigen::Vector4f& q_unit, float& norm) {
  const Eigen::Vector4f q(q_raw[0], q_raw[1], q_raw[2], q_raw[3]);
  norm = std::max(q.norm(), 1e-12f);
  q_unit = q / norm;
  const float w = q_unit[0], x = q_unit[1], y = q_unit[2], z = q_unit[3];
  Eigen::Matrix3f r;
  r << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),  //
      2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),   //
      2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
  return r;
}

struct CameraF {
  Eigen::Matrix3f R;
  Eigen::Vector3f t, centre;
  float fx, fy, cx, cy, limit_x, limit_y;
  explicit CameraF(const SplatCamera& camera)
      : R(camera.R_camera_world.cast<float>()),
        t(camera.t_camera_world.cast<float>()),
        centre(camera.centre_world().cast<float>()),
        fx(static_cast<float>(camera.fx)),
        fy(static_cast<float>(camera.fy)),
        cx(static_cast<float>(camera.cx)),
        cy(static_cast<float>(camera.cy)),
        limit_x(kFrustumMargin * 0.5f * static_cast<float>(camera.width) / static_cast<float>(camera.fx)),
        limit_y(kFrustumMargin * 0.5f * static_cast<float>(camera.height) / static_cast<float>(camera.fy)) {}
};

// The affine projection's Jacobian at the camera-frame mean (x/z, y/z clamped as above).
Eigen::Matrix<float, 2, 3> projection_jacobian(const CameraF& camera, const Eigen::Vector3f& p) {
  const float z = p.z();
  const float tx = std::clamp(p.x() / z, -camera.limit_x, camera.limit_x) * z;
  const float ty = std::clamp(p.y() / z, -camera.limit_y, camera.limit_y) * z;
  Eigen::Matrix<float, 2, 3> jacobian;
  jacobian << camera.fx / z, 0.0f, -camera.fx * tx / (z * z), 0.0f, camera.fy / z, -camera.fy * ty / (z * z);
  return jacobian;
}

int active_degree(const GaussianCloud& cloud, const RasterizerConfig& config) { return std::clamp(config.active_sh_degree, 0, cloud.sh_degree); }

// A tile's Gaussian, gathered contiguously for the pixel loops of both passes.
struct TileSplat {
  float x, y;            // mean (pixels)
  float a, b, c;         // conic
  float opacity;
  float min_power;       // ln(1 / (255 opacity)): below it alpha < 1/255
  float x0, x1, y0, y1;  // the box where alpha can reach 1/255
  Eigen::Vector3f colour;
  float depth;
};

void gather_tile(const SplatRender& render, uint32_t begin, uint32_t end, std::vector<TileSplat>& splats) {
  splats.clear();
  for (uint32_t k = begin; k < end; ++k) {
    const uint32_t g = render.tile_gaussians[k];
    const Eigen::Vector2f& mean = render.mean_2d[g];
    const Eigen::Vector2f& extent = render.extent[g];
    const Eigen::Vector3f& conic = render.conic[g];
    splats.push_back({mean.x(), mean.y(), conic[0], conic[1], conic[2], render.opacity[g], std::log(kMinAlpha / render.opacity[g]), mean.x() - extent.x(),
                      mean.x() + extent.x(), mean.y() - extent.y(), mean.y() + extent.y(), render.colour[g], render.view_depth[g]});
  }
}

// The tile's splats whose box spans pixel row y, in depth order.
void gather_row(const std::vector<TileSplat>& splats, float y, std::vector<uint32_t>& row) {
  row.clear();
  for (std::size_t j = 0; j < splats.size(); ++j) {
    if (splats[j].y0 <= y && y <= splats[j].y1) row.push_back(static_cast<uint32_t>(j));
  }
}

// Whether the splat reaches alpha >= 1/255 at pixel (px, py); its offset, Gaussian and alpha.
inline bool evaluate(const TileSplat& splat, float px, float py, float& dx, float& dy, float& gaussian, float& alpha) {
  if (px < splat.x0 || px > splat.x1 || py < splat.y0 || py > splat.y1) return false;
  dx = splat.x - px;
  dy = splat.y - py;
  const float power = -0.5f * (splat.a * dx * dx + splat.c * dy * dy) - splat.b * dx * dy;
  if (power > 0.0f || power < splat.min_power) return false;
  gaussian = std::exp(power);
  alpha = std::min(kMaxAlpha, splat.opacity * gaussian);
  return alpha >= kMinAlpha;
}

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
  const CameraF camera(camera_in);
  const auto n = static_cast<int>(cloud.size());
  const int degree = active_degree(cloud, config);
  const int coefficients = sh_coefficients(cloud.sh_degree);
  SplatRender out;
  out.width = camera_in.width;
  out.height = camera_in.height;
  out.tiles_x = (out.width + kTileSize - 1) / kTileSize;
  out.tiles_y = (out.height + kTileSize - 1) / kTileSize;
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
      const Eigen::Vector3f p_world = Eigen::Map<const Eigen::Vector3f>(&cloud.position[3 * index]);
      const Eigen::Vector3f p = camera.R * p_world + camera.t;
      if (!(p.z() > static_cast<float>(config.near))) continue;
      Eigen::Vector4f q_unit;
      float q_norm = 0.0f;
      const Eigen::Matrix3f rotation = rotation_of(&cloud.rotation[4 * index], q_unit, q_norm);
      const Eigen::Vector3f scale = Eigen::Map<const Eigen::Vector3f>(&cloud.log_scale[3 * index]).array().exp();
      const Eigen::Matrix3f m = rotation * scale.asDiagonal();
      const Eigen::Matrix3f sigma = m * m.transpose();
      const Eigen::Matrix<float, 2, 3> t = projection_jacobian(camera, p) * camera.R;
      Eigen::Matrix2f cov = t * sigma * t.transpose();
      cov(0, 0) += static_cast<float>(config.low_pass);
      cov(1, 1) += static_cast<float>(config.low_pass);
      const float det = cov(0, 0) * cov(1, 1) - cov(0, 1) * cov(0, 1);
      if (!(det > 0.0f)) continue;
      const float opacity = sigmoid(cloud.opacity_logit[index]);
      if (opacity < kMinAlpha) continue;
      const float level = 2.0f * std::log(opacity / kMinAlpha);  // q at which alpha falls to 1/255
      const Eigen::Vector2f extent(std::sqrt(level * cov(0, 0)), std::sqrt(level * cov(1, 1)));
      const Eigen::Vector2f mean(camera.fx * p.x() / p.z() + camera.cx, camera.fy * p.y() / p.z() + camera.cy);
      const auto tile_of = [](float pixel) { return static_cast<int>(std::floor(pixel / static_cast<float>(kTileSize))); };
      const Eigen::Vector4i rect(std::clamp(tile_of(mean.x() - extent.x()), 0, out.tiles_x), std::clamp(tile_of(mean.y() - extent.y()), 0, out.tiles_y),
                                 std::clamp(tile_of(mean.x() + extent.x()) + 1, 0, out.tiles_x),
                                 std::clamp(tile_of(mean.y() + extent.y()) + 1, 0, out.tiles_y));
      if (rect[2] <= rect[0] || rect[3] <= rect[1]) continue;
      // Colour along the viewing direction.
      const Eigen::Vector3f direction = (p_world - camera.centre).normalized();
      float basis[16];
      detail::sh_basis(degree, direction.x(), direction.y(), direction.z(), basis);
      Eigen::Vector3f colour = Eigen::Vector3f::Constant(0.5f);
      const float* sh = &cloud.sh[index * static_cast<std::size_t>(3 * coefficients)];
      for (int k = 0; k < sh_coefficients(degree); ++k) colour += basis[k] * Eigen::Map<const Eigen::Vector3f>(sh + 3 * k);
      uint8_t clamped = 0;
      for (int c = 0; c < 3; ++c) {
        if (colour[c] < 0.0f) {
          colour[c] = 0.0f;
          clamped |= static_cast<uint8_t>(1 << c);
        }
      }
      out.mean_2d[index] = mean;
      out.conic[index] = Eigen::Vector3f(cov(1, 1) / det, -cov(0, 1) / det, cov(0, 0) / det);
      out.colour[index] = colour;
      out.colour_clamped[index] = clamped;
      out.view_depth[index] = p.z();
      out.radius[index] = std::max(1, static_cast<int>(std::ceil(extent.maxCoeff())));
      out.extent[index] = extent;
      out.opacity[index] = opacity;
      rects[index] = rect;
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
      if (!evaluate(splats[j], static_cast<float>(x), static_cast<float>(y), dx, dy, gaussian, alpha)) continue;
      const float next = transmittance * (1.0f - alpha);
      if (next < kMinTransmittance) break;
      colour += splats[j].colour * (alpha * transmittance);
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

namespace {

// Per (tile, Gaussian) pair: dL/d(mean_2d x, y), dL/d(conic a, b, c), dL/d(colour r, g, b), dL/d(opacity).
constexpr int kSlot = 9;

// dL/dR (3 x 3) to dL/d(unit quaternion w, x, y, z).
Eigen::Vector4f rotation_gradient_to_quaternion(const Eigen::Matrix3f& dR, const Eigen::Vector4f& q) {
  const float w = q[0], x = q[1], y = q[2], z = q[3];
  Eigen::Matrix3f dw, dx, dy, dz;
  dw << 0, -z, y, z, 0, -x, -y, x, 0;
  dx << 0, y, z, y, -2 * x, -w, z, w, -2 * x;
  dy << -2 * y, x, w, x, 0, z, -w, z, -2 * y;
  dz << -2 * z, -w, x, w, -2 * z, y, x, y, 0;
  return 2.0f * Eigen::Vector4f(dR.cwiseProduct(dw).sum(), dR.cwiseProduct(dx).sum(), dR.cwiseProduct(dy).sum(), dR.cwiseProduct(dz).sum());
}

}  // namespace

void render_splats_backward(const GaussianCloud& cloud, const SplatCamera& camera_in, const RasterizerConfig& config, const SplatRender& forward,
                            const std::vector<float>& loss_gradient_image, GaussianGradients& gradients) {
  const CameraF camera(camera_in);
  const auto n = static_cast<int>(cloud.size());
  const int degree = active_degree(cloud, config);
  const int coefficients = sh_coefficients(cloud.sh_degree);
  std::vector<float> slots(forward.tile_gaussians.size() * kSlot, 0.0f);

  // 1. Per pixel, back to front: dL/d(2D mean, conic, colour, opacity) into the pair's slot.
  for_each_tile_pixel(forward, [&](uint32_t begin, const std::vector<TileSplat>& splats, const std::vector<uint32_t>& row, int x, int y, std::size_t pixel) {
    const Eigen::Vector3f dL_dpixel = Eigen::Map<const Eigen::Vector3f>(&loss_gradient_image[3 * pixel]);
    const float final_transmittance = forward.final_transmittance[pixel];
    const float background_dot = config.background.dot(dL_dpixel);
    float transmittance = final_transmittance, last_alpha = 0.0f;
    Eigen::Vector3f behind = Eigen::Vector3f::Zero(), last_colour = Eigen::Vector3f::Zero();  // colour blended behind the current one
    // The row's splats before the last contributor, back to front.
    const auto last = std::lower_bound(row.begin(), row.end(), forward.contributors[pixel]);
    for (auto it = last; it != row.begin();) {
      const uint32_t j = *--it;
      const TileSplat& splat = splats[j];
      float dx = 0.0f, dy = 0.0f, gaussian = 0.0f, alpha = 0.0f;
      if (!evaluate(splat, static_cast<float>(x), static_cast<float>(y), dx, dy, gaussian, alpha)) continue;
      transmittance /= (1.0f - alpha);
      float* slot = &slots[static_cast<std::size_t>(begin + j) * kSlot];
      behind = last_alpha * last_colour + (1.0f - last_alpha) * behind;
      last_colour = splat.colour;
      float dL_dalpha = (splat.colour - behind).dot(dL_dpixel) * transmittance;
      for (int c = 0; c < 3; ++c) slot[5 + c] += alpha * transmittance * dL_dpixel[c];
      last_alpha = alpha;
      dL_dalpha += -final_transmittance / (1.0f - alpha) * background_dot;
      if (splat.opacity * gaussian >= kMaxAlpha) continue;  // clamped: alpha does not move with the Gaussian
      const float dL_dgaussian = splat.opacity * dL_dalpha;
      const float gdx = gaussian * dx, gdy = gaussian * dy;
      slot[0] += dL_dgaussian * (-gdx * splat.a - gdy * splat.b);
      slot[1] += dL_dgaussian * (-gdy * splat.c - gdx * splat.b);
      slot[2] += -0.5f * gdx * dx * dL_dgaussian;
      slot[3] += -gdx * dy * dL_dgaussian;
      slot[4] += -0.5f * gdy * dy * dL_dgaussian;
      slot[8] += gaussian * dL_dalpha;
    }
  });

  // 2. The pairs summed per Gaussian in list order (deterministic).
  std::vector<float> per_gaussian(static_cast<std::size_t>(n) * kSlot, 0.0f);
  for (std::size_t k = 0; k < forward.tile_gaussians.size(); ++k) {
    float* sum = &per_gaussian[static_cast<std::size_t>(forward.tile_gaussians[k]) * kSlot];
    const float* slot = &slots[k * kSlot];
    for (int j = 0; j < kSlot; ++j) sum[j] += slot[j];
  }

  // 3. Per Gaussian: through the projection, the 2D covariance, scale, rotation and colour.
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 1024), [&](const tbb::blocked_range<int>& range) {
    for (int i = range.begin(); i != range.end(); ++i) {
      const auto index = static_cast<std::size_t>(i);
      if (forward.radius[index] == 0) continue;
      const float* g = &per_gaussian[index * kSlot];
      const Eigen::Vector2f dL_dmean(g[0], g[1]);
      gradients.screen_gradient_norm[index] += Eigen::Vector2f(dL_dmean.x() * 0.5f * static_cast<float>(forward.width), dL_dmean.y() * 0.5f * static_cast<float>(forward.height)).norm();
      gradients.visible_views[index] += 1;
      const float opacity = forward.opacity[index];
      gradients.opacity_logit[index] += g[8] * opacity * (1.0f - opacity);

      const Eigen::Vector3f p_world = Eigen::Map<const Eigen::Vector3f>(&cloud.position[3 * index]);
      const Eigen::Vector3f p = camera.R * p_world + camera.t;
      Eigen::Vector3f dL_dp_world = Eigen::Vector3f::Zero();

      // Colour (spherical harmonics; clamped channels pass nothing).
      Eigen::Vector3f dL_dcolour(g[5], g[6], g[7]);
      for (int c = 0; c < 3; ++c) {
        if ((forward.colour_clamped[index] >> c) & 1) dL_dcolour[c] = 0.0f;
      }
      const Eigen::Vector3f view = p_world - camera.centre;
      const float view_norm = std::max(view.norm(), 1e-12f);
      const Eigen::Vector3f direction = view / view_norm;
      using Jet = ceres::Jet<float, 3>;
      Jet basis[16];
      detail::sh_basis(degree, Jet(direction.x(), 0), Jet(direction.y(), 1), Jet(direction.z(), 2), basis);
      const float* sh = &cloud.sh[index * static_cast<std::size_t>(3 * coefficients)];
      float* dL_dsh = &gradients.sh[index * static_cast<std::size_t>(3 * coefficients)];
      Eigen::Vector3f dL_ddirection = Eigen::Vector3f::Zero();
      for (int k = 0; k < sh_coefficients(degree); ++k) {
        const Eigen::Map<const Eigen::Vector3f> coefficient(sh + 3 * k);
        for (int c = 0; c < 3; ++c) dL_dsh[3 * k + c] += basis[k].a * dL_dcolour[c];
        dL_ddirection += coefficient.dot(dL_dcolour) * basis[k].v;
      }
      dL_dp_world += (dL_ddirection - direction * direction.dot(dL_ddirection)) / view_norm;

      // Conic -> 2D covariance -> (J W) and Sigma.
      Eigen::Vector4f q_unit;
      float q_norm = 0.0f;
      const Eigen::Matrix3f rotation = rotation_of(&cloud.rotation[4 * index], q_unit, q_norm);
      const Eigen::Vector3f scale = Eigen::Map<const Eigen::Vector3f>(&cloud.log_scale[3 * index]).array().exp();
      const Eigen::Matrix3f m = rotation * scale.asDiagonal();
      const Eigen::Matrix3f sigma = m * m.transpose();
      const Eigen::Matrix<float, 2, 3> jacobian = projection_jacobian(camera, p);
      const Eigen::Matrix<float, 2, 3> t = jacobian * camera.R;
      const Eigen::Vector3f& conic = forward.conic[index];
      Eigen::Matrix2f conic_matrix;
      conic_matrix << conic[0], conic[1], conic[1], conic[2];
      Eigen::Matrix2f dL_dconic;
      dL_dconic << g[2], 0.5f * g[3], 0.5f * g[3], g[4];
      const Eigen::Matrix2f dL_dcov = -conic_matrix * dL_dconic * conic_matrix;
      const Eigen::Matrix3f dL_dsigma = t.transpose() * dL_dcov * t;
      const Eigen::Matrix<float, 2, 3> dL_dt = 2.0f * dL_dcov * t * sigma;
      const Eigen::Matrix<float, 2, 3> dL_djacobian = dL_dt * camera.R.transpose();

      // Projection: the mean in pixels and the Jacobian's dependence on the camera-frame mean.
      const float z = p.z(), z2 = z * z, z3 = z2 * z;
      const bool inside_x = std::abs(p.x() / z) <= camera.limit_x, inside_y = std::abs(p.y() / z) <= camera.limit_y;
      const float tx_over_z = std::clamp(p.x() / z, -camera.limit_x, camera.limit_x), ty_over_z = std::clamp(p.y() / z, -camera.limit_y, camera.limit_y);
      Eigen::Vector3f dL_dp(dL_dmean.x() * camera.fx / z, dL_dmean.y() * camera.fy / z,
                            -dL_dmean.x() * camera.fx * p.x() / z2 - dL_dmean.y() * camera.fy * p.y() / z2);
      dL_dp.z() += -dL_djacobian(0, 0) * camera.fx / z2 - dL_djacobian(1, 1) * camera.fy / z2;
      if (inside_x) {
        dL_dp.x() += -dL_djacobian(0, 2) * camera.fx / z2;
        dL_dp.z() += dL_djacobian(0, 2) * 2.0f * camera.fx * p.x() / z3;
      } else {
        dL_dp.z() += dL_djacobian(0, 2) * camera.fx * tx_over_z / z2;
      }
      if (inside_y) {
        dL_dp.y() += -dL_djacobian(1, 2) * camera.fy / z2;
        dL_dp.z() += dL_djacobian(1, 2) * 2.0f * camera.fy * p.y() / z3;
      } else {
        dL_dp.z() += dL_djacobian(1, 2) * camera.fy * ty_over_z / z2;
      }
      dL_dp_world += camera.R.transpose() * dL_dp;
      for (int a = 0; a < 3; ++a) gradients.position[3 * index + static_cast<std::size_t>(a)] += dL_dp_world[a];

      // Sigma = M M^T, M = R diag(s).
      const Eigen::Matrix3f dL_dm = 2.0f * dL_dsigma * m;
      Eigen::Matrix3f dL_drotation;
      for (int a = 0; a < 3; ++a) {
        gradients.log_scale[3 * index + static_cast<std::size_t>(a)] += scale[a] * rotation.col(a).dot(dL_dm.col(a));
        dL_drotation.col(a) = scale[a] * dL_dm.col(a);
      }
      const Eigen::Vector4f dL_dq_unit = rotation_gradient_to_quaternion(dL_drotation, q_unit);
      const Eigen::Vector4f dL_dq = (dL_dq_unit - q_unit * q_unit.dot(dL_dq_unit)) / q_norm;
      for (int a = 0; a < 4; ++a) gradients.rotation[4 * index + static_cast<std::size_t>(a)] += dL_dq[a];
    }
  });
}

}  // namespace hanzo::fusion::neural
