#pragma once
// The arithmetic of the splat rasterizer (splat_rasterizer.hpp: the equations and conventions),
// written once for the CPU passes and the CUDA kernels: plain floats, no Eigen, host and device.
// The schedules around it (tiles, sorting, threads) live in splat_rasterizer.cpp and
// cuda/splat_rasterizer.cu.
//
// Matrices are row-major float arrays: m[3 * row + col] (3 x 3), m[3 * row + col] (2 x 3).

#include <cmath>
#include <cstdint>

#include "host_device.hpp"
#include "spherical_harmonics.hpp"

namespace hanzo::fusion::neural::kernels {

inline constexpr int kTileSize = 16;
inline constexpr float kMinAlpha = 1.0f / 255.0f;
inline constexpr float kMaxAlpha = 0.99f;
inline constexpr float kMinTransmittance = 1e-4f;
// |x/z| and |y/z| are clamped to this multiple of the half field of view in the Jacobian (as the
// reference implementation does): Gaussians far outside the view get a bounded footprint.
inline constexpr float kFrustumMargin = 1.3f;
/// Per (tile, Gaussian) pair of the backward pass: dL/d(mean_2d x, y), dL/d(conic a, b, c),
/// dL/d(colour r, g, b), dL/d(opacity).
inline constexpr int kPairGradients = 9;

/// The camera in floats: R_camera_world row-major, t_camera_world, the centre in the world.
struct CameraParams {
  float R[9];
  float t[3];
  float centre[3];
  float fx, fy, cx, cy;
  float limit_x, limit_y;  ///< kFrustumMargin x the half field of view, as tangents
  int width, height, tiles_x, tiles_y;
};

/// One Gaussian as the camera sees it (written only when it is drawn).
struct Projection {
  float mean[2];    ///< pixels
  float conic[3];   ///< Sigma'^-1 as (a, b, c): [[a, b], [b, c]]
  float colour[3];  ///< clamped at 0
  float depth;      ///< z in the optical frame
  float extent[2];  ///< half-widths (pixels) of the box where alpha can reach 1/255
  float opacity;    ///< sigmoid(opacity_logit)
  int radius;       ///< the box's larger half-width, rounded up (>= 1)
  uint32_t clamped;  ///< per channel bit: the colour was clamped at 0
  int rect[4];       ///< tiles x0, y0, x1, y1 (x1, y1 exclusive)
};

/// A tile's Gaussian as the pixel loops read it.
struct TileSplat {
  float x, y;            ///< mean (pixels)
  float a, b, c;         ///< conic
  float opacity;
  float min_power;       ///< ln(1 / (255 opacity)): below it alpha < 1/255
  float x0, x1, y0, y1;  ///< the box where alpha can reach 1/255
  float colour[3];
  float depth;
};

HANZO_HD float clamp_value(float value, float low, float high) { return value < low ? low : (value > high ? high : value); }
HANZO_HD float sigmoid_value(float x) { return 1.0f / (1.0f + expf(-x)); }

/// The unit quaternion (w, x, y, z) of the raw one, its norm and its rotation matrix.
HANZO_HD void quaternion_rotation(const float* q_raw, float* q_unit, float& norm, float* rotation) {
  norm = sqrtf(q_raw[0] * q_raw[0] + q_raw[1] * q_raw[1] + q_raw[2] * q_raw[2] + q_raw[3] * q_raw[3]);
  norm = norm > 1e-12f ? norm : 1e-12f;
  for (int k = 0; k < 4; ++k) q_unit[k] = q_raw[k] / norm;
  const float w = q_unit[0], x = q_unit[1], y = q_unit[2], z = q_unit[3];
  const float r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - w * z),     2 * (x * z + w * y),  //
                      2 * (x * y + w * z),     1 - 2 * (x * x + z * z), 2 * (y * z - w * x),  //
                      2 * (x * z - w * y),     2 * (y * z + w * x),     1 - 2 * (x * x + y * y)};
  for (int k = 0; k < 9; ++k) rotation[k] = r[k];
}

/// Sigma = M M^T with M = R diag(exp(log_scale)) (paper eq. 6); also returns M and the scales.
HANZO_HD void covariance_3d(const float* rotation, const float* log_scale, float* scale, float* m, float* sigma) {
  for (int a = 0; a < 3; ++a) scale[a] = expf(log_scale[a]);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) m[3 * r + c] = rotation[3 * r + c] * scale[c];
  }
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) sigma[3 * r + c] = m[3 * r] * m[3 * c] + m[3 * r + 1] * m[3 * c + 1] + m[3 * r + 2] * m[3 * c + 2];
  }
}

/// p = R_camera_world p_world + t_camera_world.
HANZO_HD void to_camera(const CameraParams& camera, const float* p_world, float* p) {
  for (int r = 0; r < 3; ++r) p[r] = camera.R[3 * r] * p_world[0] + camera.R[3 * r + 1] * p_world[1] + camera.R[3 * r + 2] * p_world[2] + camera.t[r];
}

/// T = J W: the affine projection's Jacobian J at the camera-frame mean p (x/z, y/z clamped as
/// above) times the camera's rotation W (2 x 3, row-major).
HANZO_HD void projection_times_rotation(const CameraParams& camera, const float* p, float* jacobian, float* t) {
  const float z = p[2];
  const float tx = clamp_value(p[0] / z, -camera.limit_x, camera.limit_x) * z;
  const float ty = clamp_value(p[1] / z, -camera.limit_y, camera.limit_y) * z;
  jacobian[0] = camera.fx / z;
  jacobian[1] = 0.0f;
  jacobian[2] = -camera.fx * tx / (z * z);
  jacobian[3] = 0.0f;
  jacobian[4] = camera.fy / z;
  jacobian[5] = -camera.fy * ty / (z * z);
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 3; ++c) t[3 * r + c] = jacobian[3 * r] * camera.R[c] + jacobian[3 * r + 1] * camera.R[3 + c] + jacobian[3 * r + 2] * camera.R[6 + c];
  }
}

/// The unit viewing direction from the camera's centre to the point and the distance.
HANZO_HD float view_direction(const CameraParams& camera, const float* p_world, float* direction) {
  const float v[3] = {p_world[0] - camera.centre[0], p_world[1] - camera.centre[1], p_world[2] - camera.centre[2]};
  float norm = sqrtf(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  norm = norm > 1e-12f ? norm : 1e-12f;
  for (int a = 0; a < 3; ++a) direction[a] = v[a] / norm;
  return norm;
}

/// Projects one Gaussian (its parameters as the cloud stores them; `sh` its 3 (d+1)^2
/// coefficients, interleaved by channel, of which the first (degree+1)^2 are used). False: not
/// drawn (behind the near plane, degenerate, transparent or outside every tile).
HANZO_HD bool project_gaussian(const float* position, const float* log_scale, const float* rotation_raw, float opacity_logit, const float* sh, int degree,
                               const CameraParams& camera, float near, float low_pass, Projection& out) {
  float p[3];
  to_camera(camera, position, p);
  if (!(p[2] > near)) return false;
  float q_unit[4], q_norm, rotation[9], scale[3], m[9], sigma[9], jacobian[6], t[6];
  quaternion_rotation(rotation_raw, q_unit, q_norm, rotation);
  covariance_3d(rotation, log_scale, scale, m, sigma);
  projection_times_rotation(camera, p, jacobian, t);
  // cov = T Sigma T^T (paper eq. 5) plus the low-pass filter.
  float t_sigma[6];
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 3; ++c) t_sigma[3 * r + c] = t[3 * r] * sigma[c] + t[3 * r + 1] * sigma[3 + c] + t[3 * r + 2] * sigma[6 + c];
  }
  const float cov00 = t_sigma[0] * t[0] + t_sigma[1] * t[1] + t_sigma[2] * t[2] + low_pass;
  const float cov01 = t_sigma[0] * t[3] + t_sigma[1] * t[4] + t_sigma[2] * t[5];
  const float cov11 = t_sigma[3] * t[3] + t_sigma[4] * t[4] + t_sigma[5] * t[5] + low_pass;
  const float det = cov00 * cov11 - cov01 * cov01;
  if (!(det > 0.0f)) return false;
  const float opacity = sigmoid_value(opacity_logit);
  if (opacity < kMinAlpha) return false;
  const float level = 2.0f * logf(opacity / kMinAlpha);  // q at which alpha falls to 1/255
  const float extent_x = sqrtf(level * cov00), extent_y = sqrtf(level * cov11);
  const float mean_x = camera.fx * p[0] / p[2] + camera.cx, mean_y = camera.fy * p[1] / p[2] + camera.cy;
  const auto tile_of = [](float pixel) { return static_cast<int>(floorf(pixel / static_cast<float>(kTileSize))); };
  const auto clamp_tile = [](int tile, int count) { return tile < 0 ? 0 : (tile > count ? count : tile); };
  const int rect[4] = {clamp_tile(tile_of(mean_x - extent_x), camera.tiles_x), clamp_tile(tile_of(mean_y - extent_y), camera.tiles_y),
                       clamp_tile(tile_of(mean_x + extent_x) + 1, camera.tiles_x), clamp_tile(tile_of(mean_y + extent_y) + 1, camera.tiles_y)};
  if (rect[2] <= rect[0] || rect[3] <= rect[1]) return false;
  // Colour along the viewing direction.
  float direction[3], basis[16];
  view_direction(camera, position, direction);
  detail::sh_basis(degree, direction[0], direction[1], direction[2], basis);
  out.clamped = 0;
  for (int c = 0; c < 3; ++c) {
    float colour = 0.5f;
    for (int k = 0; k < (degree + 1) * (degree + 1); ++k) colour += basis[k] * sh[3 * k + c];
    if (colour < 0.0f) {
      colour = 0.0f;
      out.clamped |= 1u << c;
    }
    out.colour[c] = colour;
  }
  out.mean[0] = mean_x;
  out.mean[1] = mean_y;
  out.conic[0] = cov11 / det;
  out.conic[1] = -cov01 / det;
  out.conic[2] = cov00 / det;
  out.depth = p[2];
  out.extent[0] = extent_x;
  out.extent[1] = extent_y;
  out.opacity = opacity;
  const float larger = extent_x > extent_y ? extent_x : extent_y;
  out.radius = static_cast<int>(ceilf(larger)) > 1 ? static_cast<int>(ceilf(larger)) : 1;
  for (int k = 0; k < 4; ++k) out.rect[k] = rect[k];
  return true;
}

HANZO_HD TileSplat make_tile_splat(const float* mean, const float* extent, const float* conic, float opacity, const float* colour, float depth) {
  return {mean[0],        mean[1], conic[0], conic[1], conic[2], opacity, logf(kMinAlpha / opacity), mean[0] - extent[0], mean[0] + extent[0],
          mean[1] - extent[1], mean[1] + extent[1], {colour[0], colour[1], colour[2]}, depth};
}

/// Whether the splat reaches alpha >= 1/255 at pixel (px, py); its offset, Gaussian and alpha
/// (paper eq. 3's alpha_i = min(0.99, o_i exp(-0.5 d^T Sigma'^-1 d))).
HANZO_HD bool evaluate_splat(const TileSplat& splat, float px, float py, float& dx, float& dy, float& gaussian, float& alpha) {
  if (px < splat.x0 || px > splat.x1 || py < splat.y0 || py > splat.y1) return false;
  dx = splat.x - px;
  dy = splat.y - py;
  const float power = -0.5f * (splat.a * dx * dx + splat.c * dy * dy) - splat.b * dx * dy;
  if (power > 0.0f || power < splat.min_power) return false;
  gaussian = expf(power);
  alpha = splat.opacity * gaussian < kMaxAlpha ? splat.opacity * gaussian : kMaxAlpha;
  return alpha >= kMinAlpha;
}

/// One pixel's backward walk, back to front (the paper's Sec. 6).
struct PixelBackward {
  float dL_dpixel[3];
  float final_transmittance;
  float background_dot;  ///< background . dL/dpixel
  float transmittance;   ///< in front of the splat being visited
  float last_alpha = 0.0f;
  float behind[3] = {0.0f, 0.0f, 0.0f};  ///< colour blended behind the splat being visited
  float last_colour[3] = {0.0f, 0.0f, 0.0f};

  HANZO_HD PixelBackward(const float* dL_dpixel_in, float final_transmittance_in, const float* background)
      : dL_dpixel{dL_dpixel_in[0], dL_dpixel_in[1], dL_dpixel_in[2]},
        final_transmittance(final_transmittance_in),
        background_dot(background[0] * dL_dpixel_in[0] + background[1] * dL_dpixel_in[1] + background[2] * dL_dpixel_in[2]),
        transmittance(final_transmittance_in) {}

  /// The next splat (towards the camera) that the forward pass blended at this pixel: its
  /// gradients (kPairGradients) written to `pair`.
  HANZO_HD void step(const TileSplat& splat, float dx, float dy, float gaussian, float alpha, float* pair) {
    transmittance /= (1.0f - alpha);
    float dL_dalpha = 0.0f;
    for (int c = 0; c < 3; ++c) {
      behind[c] = last_alpha * last_colour[c] + (1.0f - last_alpha) * behind[c];
      last_colour[c] = splat.colour[c];
      dL_dalpha += (splat.colour[c] - behind[c]) * dL_dpixel[c];
      pair[5 + c] = alpha * transmittance * dL_dpixel[c];
    }
    dL_dalpha *= transmittance;
    last_alpha = alpha;
    dL_dalpha += -final_transmittance / (1.0f - alpha) * background_dot;
    for (int k = 0; k < 5; ++k) pair[k] = 0.0f;
    pair[8] = 0.0f;
    if (splat.opacity * gaussian >= kMaxAlpha) return;  // clamped: alpha does not move with the Gaussian
    const float dL_dgaussian = splat.opacity * dL_dalpha;
    const float gdx = gaussian * dx, gdy = gaussian * dy;
    pair[0] = dL_dgaussian * (-gdx * splat.a - gdy * splat.b);
    pair[1] = dL_dgaussian * (-gdy * splat.c - gdx * splat.b);
    pair[2] = -0.5f * gdx * dx * dL_dgaussian;
    pair[3] = -gdx * dy * dL_dgaussian;
    pair[4] = -0.5f * gdy * dy * dL_dgaussian;
    pair[8] = gaussian * dL_dalpha;
  }
};

/// A value and its gradient with respect to three inputs (the SH basis' Jacobian).
struct Dual3 {
  float a = 0.0f;
  float v[3] = {0.0f, 0.0f, 0.0f};
  Dual3() = default;
  HANZO_HD explicit Dual3(double value) : a(static_cast<float>(value)) {}
  HANZO_HD Dual3(float value, int input) : a(value) { v[input] = 1.0f; }
};
HANZO_HD Dual3 operator+(const Dual3& l, const Dual3& r) {
  Dual3 out;
  out.a = l.a + r.a;
  for (int k = 0; k < 3; ++k) out.v[k] = l.v[k] + r.v[k];
  return out;
}
HANZO_HD Dual3 operator-(const Dual3& l, const Dual3& r) {
  Dual3 out;
  out.a = l.a - r.a;
  for (int k = 0; k < 3; ++k) out.v[k] = l.v[k] - r.v[k];
  return out;
}
HANZO_HD Dual3 operator*(const Dual3& l, const Dual3& r) {
  Dual3 out;
  out.a = l.a * r.a;
  for (int k = 0; k < 3; ++k) out.v[k] = l.a * r.v[k] + l.v[k] * r.a;
  return out;
}

/// dL/dR (3 x 3) to dL/d(unit quaternion w, x, y, z).
HANZO_HD void rotation_gradient_to_quaternion(const float* dR, const float* q, float* dq) {
  const float w = q[0], x = q[1], y = q[2], z = q[3];
  const float dw[9] = {0, -z, y, z, 0, -x, -y, x, 0};
  const float dx[9] = {0, y, z, y, -2 * x, -w, z, w, -2 * x};
  const float dy[9] = {-2 * y, x, w, x, 0, z, -w, z, -2 * y};
  const float dz[9] = {-2 * z, -w, x, w, -2 * z, y, x, y, 0};
  for (int k = 0; k < 4; ++k) dq[k] = 0.0f;
  for (int k = 0; k < 9; ++k) {
    dq[0] += 2.0f * dR[k] * dw[k];
    dq[1] += 2.0f * dR[k] * dx[k];
    dq[2] += 2.0f * dR[k] * dy[k];
    dq[3] += 2.0f * dR[k] * dz[k];
  }
}

/// Where one Gaussian's gradients go (the cloud's layout at its index); every value is added to.
struct GaussianGradientOut {
  float* position;       ///< 3
  float* log_scale;      ///< 3
  float* rotation;       ///< 4
  float* opacity_logit;  ///< 1
  float* sh;             ///< 3 (degree+1)^2 of the cloud's stride
};

/// From one drawn Gaussian's summed pair gradients `pair` (kPairGradients) to its parameters:
/// through the projection, the 2D covariance, scale, rotation and colour (clamped channels pass
/// nothing). Returns |dL/d(mean in normalized device coordinates)|, the densification statistic.
HANZO_HD float gaussian_backward(const float* position, const float* log_scale, const float* rotation_raw, const float* sh, int degree,
                                 const CameraParams& camera, const Projection& projection, const float* pair, GaussianGradientOut out) {
  const float dL_dmean_x = pair[0], dL_dmean_y = pair[1];
  const float ndc_x = dL_dmean_x * 0.5f * static_cast<float>(camera.width), ndc_y = dL_dmean_y * 0.5f * static_cast<float>(camera.height);
  out.opacity_logit[0] += pair[8] * projection.opacity * (1.0f - projection.opacity);

  float p[3];
  to_camera(camera, position, p);
  float dL_dp_world[3] = {0.0f, 0.0f, 0.0f};

  // Colour (spherical harmonics).
  float dL_dcolour[3];
  for (int c = 0; c < 3; ++c) dL_dcolour[c] = ((projection.clamped >> c) & 1u) ? 0.0f : pair[5 + c];
  float direction[3];
  const float view_norm = view_direction(camera, position, direction);
  Dual3 basis[16];
  detail::sh_basis(degree, Dual3(direction[0], 0), Dual3(direction[1], 1), Dual3(direction[2], 2), basis);
  float dL_ddirection[3] = {0.0f, 0.0f, 0.0f};
  for (int k = 0; k < (degree + 1) * (degree + 1); ++k) {
    float coefficient_dot = 0.0f;
    for (int c = 0; c < 3; ++c) {
      out.sh[3 * k + c] += basis[k].a * dL_dcolour[c];
      coefficient_dot += sh[3 * k + c] * dL_dcolour[c];
    }
    for (int a = 0; a < 3; ++a) dL_ddirection[a] += coefficient_dot * basis[k].v[a];
  }
  const float along = direction[0] * dL_ddirection[0] + direction[1] * dL_ddirection[1] + direction[2] * dL_ddirection[2];
  for (int a = 0; a < 3; ++a) dL_dp_world[a] += (dL_ddirection[a] - direction[a] * along) / view_norm;

  // Conic -> 2D covariance -> (J W) and Sigma.
  float q_unit[4], q_norm, rotation[9], scale[3], m[9], sigma[9], jacobian[6], t[6];
  quaternion_rotation(rotation_raw, q_unit, q_norm, rotation);
  covariance_3d(rotation, log_scale, scale, m, sigma);
  projection_times_rotation(camera, p, jacobian, t);
  const float conic[4] = {projection.conic[0], projection.conic[1], projection.conic[1], projection.conic[2]};
  const float dL_dconic[4] = {pair[2], 0.5f * pair[3], 0.5f * pair[3], pair[4]};
  float product[4], dL_dcov[4];  // dL/dcov = -C dL/dC C
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 2; ++c) product[2 * r + c] = conic[2 * r] * dL_dconic[c] + conic[2 * r + 1] * dL_dconic[2 + c];
  }
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 2; ++c) dL_dcov[2 * r + c] = -(product[2 * r] * conic[c] + product[2 * r + 1] * conic[2 + c]);
  }
  float dL_dsigma[9], dcov_t[6], dL_dt[6], dL_djacobian[6];
  for (int r = 0; r < 2; ++r) {  // dcov_t = dL/dcov T (2 x 3)
    for (int c = 0; c < 3; ++c) dcov_t[3 * r + c] = dL_dcov[2 * r] * t[c] + dL_dcov[2 * r + 1] * t[3 + c];
  }
  for (int r = 0; r < 3; ++r) {  // dL/dSigma = T^T dL/dcov T
    for (int c = 0; c < 3; ++c) dL_dsigma[3 * r + c] = t[r] * dcov_t[c] + t[3 + r] * dcov_t[3 + c];
  }
  for (int r = 0; r < 2; ++r) {  // dL/dT = 2 dL/dcov T Sigma
    for (int c = 0; c < 3; ++c) dL_dt[3 * r + c] = 2.0f * (dcov_t[3 * r] * sigma[c] + dcov_t[3 * r + 1] * sigma[3 + c] + dcov_t[3 * r + 2] * sigma[6 + c]);
  }
  for (int r = 0; r < 2; ++r) {  // dL/dJ = dL/dT W^T
    for (int c = 0; c < 3; ++c) {
      dL_djacobian[3 * r + c] = dL_dt[3 * r] * camera.R[3 * c] + dL_dt[3 * r + 1] * camera.R[3 * c + 1] + dL_dt[3 * r + 2] * camera.R[3 * c + 2];
    }
  }

  // Projection: the mean in pixels and the Jacobian's dependence on the camera-frame mean.
  const float z = p[2], z2 = z * z, z3 = z2 * z;
  const bool inside_x = fabsf(p[0] / z) <= camera.limit_x, inside_y = fabsf(p[1] / z) <= camera.limit_y;
  const float tx_over_z = clamp_value(p[0] / z, -camera.limit_x, camera.limit_x), ty_over_z = clamp_value(p[1] / z, -camera.limit_y, camera.limit_y);
  float dL_dp[3] = {dL_dmean_x * camera.fx / z, dL_dmean_y * camera.fy / z, -dL_dmean_x * camera.fx * p[0] / z2 - dL_dmean_y * camera.fy * p[1] / z2};
  dL_dp[2] += -dL_djacobian[0] * camera.fx / z2 - dL_djacobian[4] * camera.fy / z2;
  if (inside_x) {
    dL_dp[0] += -dL_djacobian[2] * camera.fx / z2;
    dL_dp[2] += dL_djacobian[2] * 2.0f * camera.fx * p[0] / z3;
  } else {
    dL_dp[2] += dL_djacobian[2] * camera.fx * tx_over_z / z2;
  }
  if (inside_y) {
    dL_dp[1] += -dL_djacobian[5] * camera.fy / z2;
    dL_dp[2] += dL_djacobian[5] * 2.0f * camera.fy * p[1] / z3;
  } else {
    dL_dp[2] += dL_djacobian[5] * camera.fy * ty_over_z / z2;
  }
  for (int a = 0; a < 3; ++a) {
    dL_dp_world[a] += camera.R[a] * dL_dp[0] + camera.R[3 + a] * dL_dp[1] + camera.R[6 + a] * dL_dp[2];
    out.position[a] += dL_dp_world[a];
  }

  // Sigma = M M^T, M = R diag(s): dL/dM = 2 dL/dSigma M.
  float dL_drotation[9];
  for (int c = 0; c < 3; ++c) {
    float dL_dm_col[3];
    for (int r = 0; r < 3; ++r) dL_dm_col[r] = 2.0f * (dL_dsigma[3 * r] * m[c] + dL_dsigma[3 * r + 1] * m[3 + c] + dL_dsigma[3 * r + 2] * m[6 + c]);
    out.log_scale[c] += scale[c] * (rotation[c] * dL_dm_col[0] + rotation[3 + c] * dL_dm_col[1] + rotation[6 + c] * dL_dm_col[2]);
    for (int r = 0; r < 3; ++r) dL_drotation[3 * r + c] = scale[c] * dL_dm_col[r];
  }
  float dL_dq_unit[4];
  rotation_gradient_to_quaternion(dL_drotation, q_unit, dL_dq_unit);
  const float q_dot = q_unit[0] * dL_dq_unit[0] + q_unit[1] * dL_dq_unit[1] + q_unit[2] * dL_dq_unit[2] + q_unit[3] * dL_dq_unit[3];
  for (int k = 0; k < 4; ++k) out.rotation[k] += (dL_dq_unit[k] - q_unit[k] * q_dot) / q_norm;
  return sqrtf(ndc_x * ndc_x + ndc_y * ndc_y);
}

}  // namespace hanzo::fusion::neural::kernels

namespace hanzo::fusion::neural {
struct SplatCamera;
/// The camera's floats for the kernels (splat_rasterizer.cpp).
kernels::CameraParams camera_params(const SplatCamera& camera);
}  // namespace hanzo::fusion::neural
