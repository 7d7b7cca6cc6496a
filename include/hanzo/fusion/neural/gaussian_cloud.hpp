#pragma once
// GaussianCloud: the scene representation of 3D Gaussian splatting (Kerbl et al., SIGGRAPH 2023).
//
// Each Gaussian i has, in the world frame (metres, or the scene's units):
//   position      mean mu_i (3 floats)
//   log_scale     log of the standard deviations along its own axes (3 floats): s = exp(log_scale)
//   rotation      quaternion (w, x, y, z), not necessarily unit (normalized where used): R_i
//   opacity_logit o_i = sigmoid(opacity_logit)
//   sh            spherical-harmonics colour coefficients, (degree + 1)^2 per channel, stored
//                 coefficient-major: sh[i][k][c] for coefficient k and channel c (RGB); k = 0 is
//                 the view-independent ("DC") term. The colour seen along unit direction d (from
//                 the camera centre to the mean) is max(0, sum_k Y_k(d) sh[k] + 0.5).
// The covariance is Sigma_i = R_i S_i S_i^T R_i^T, S_i = diag(s) (paper eq. 6).
//
// Arrays are structure-of-arrays so that the optimizer treats each parameter group as one flat
// vector (parameters()).

#include <cmath>
#include <cstddef>
#include <span>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace hanzo::fusion::neural {

inline constexpr int kMaxShDegree = 3;
/// Coefficients per channel of degree `degree`: (degree + 1)^2.
constexpr int sh_coefficients(int degree) { return (degree + 1) * (degree + 1); }

struct GaussianCloud {
  int sh_degree = kMaxShDegree;  ///< degree the coefficients are stored for (0..3)
  std::vector<float> position;       ///< 3 per Gaussian
  std::vector<float> log_scale;      ///< 3 per Gaussian
  std::vector<float> rotation;       ///< 4 per Gaussian (w, x, y, z)
  std::vector<float> opacity_logit;  ///< 1 per Gaussian
  std::vector<float> sh;             ///< 3 (degree+1)^2 per Gaussian

  std::size_t size() const { return opacity_logit.size(); }
  int sh_floats() const { return 3 * sh_coefficients(sh_degree); }
  /// Appends one Gaussian: `sh_dc` is the k = 0 coefficient per channel, the others zero.
  void add(const Eigen::Vector3f& mean, const Eigen::Vector3f& log_scales, const Eigen::Vector4f& rotation_wxyz, float opacity_logit_value,
           const Eigen::Vector3f& sh_dc);
  /// Keeps the Gaussians whose `keep` entry is true, in order.
  void filter(const std::vector<bool>& keep);
  /// The parameter groups as flat spans, in the order position, log_scale, rotation,
  /// opacity_logit, sh (the optimizer's and the gradients' layout).
  std::vector<std::span<float>> parameters();
  /// True when every array has the size the count and degree need and every value is finite.
  bool consistent() const;
};

/// Per-Gaussian gradients of a loss, laid out as the cloud's arrays.
struct GaussianGradients {
  std::vector<float> position, log_scale, rotation, opacity_logit, sh;
  /// |dL/d(mean in normalized device coordinates)| summed over the views it was drawn in, and
  /// that count (the densification statistic of the paper's Sec. 5.2).
  std::vector<float> screen_gradient_norm;
  std::vector<int> visible_views;
  void resize_like(const GaussianCloud& cloud);
  void set_zero();
  std::vector<std::span<float>> parameters();
};

/// sigmoid and its inverse (opacity).
inline float sigmoid(float x) { return 1.0f / (1.0f + std::exp(-x)); }
inline float logit(float p) { return std::log(p / (1.0f - p)); }
/// The DC coefficient that shows `colour` (0..1) regardless of direction: (colour - 0.5) / Y_0.
Eigen::Vector3f sh_dc_of_colour(const Eigen::Vector3f& colour);

}  // namespace hanzo::fusion::neural
