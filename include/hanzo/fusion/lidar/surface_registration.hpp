#pragma once
// Registration of points to the surfaces of a cloud::VoxelHashMap (the scan-to-map step of
// LidarOdometry; also usable to relocalize a scan against a saved local map).
//
// Gauss-Newton on SE3 with the right perturbation T <- T Exp(delta), delta = (rho, phi).
// Association (as FAST-LIO's, Xu et al. 2022, with a shape test): each source point q = T p
// gets the `neighbours` nearest map points within max_neighbour_distance. When the nearest
// one carries a measured normal (cloud/scan_normals.hpp) and at least min_neighbours / 2 + 1
// of them agree with it (dot >= normal_agreement), the residual is point-to-plane on their
// mean normal and mean position. Otherwise their covariance's eigenvalues l0 <= l1 <= l2
// give the local shape:
// - line (l1 < line_ratio l2): when within vertical_line_angle of the map's z axis (poles,
//   trunks, vertical edges) the residual is the 2-vector of q - mean perpendicular to it;
//   other lines give none (mostly one ring's arc over the ground or a wall: a residual
//   toward it pulls a moving sensor back to where that ring was);
// - plane (l0 < plane_ratio l1): point-to-plane residual n . (q - mean) (Chen & Medioni 1992);
// - otherwise (volumes: foliage, clutter) no residual.
// Surfaces are fitted again when the estimate has moved more than reassociation_translation
// or reassociation_rotation since the last fit (a plane stays valid under small motion), so a
// well-predicted scan is usually associated once or twice. Residuals are weighted by
// Geman-McClure; its width starts at initial_kernel_width and halves down to kernel_width after
// each step that moved the points (translation + rotation x their mean range) by less than
// half the width (coarse to fine: a poor prediction, such as the constant-velocity model at the
// start of a turn, still converges, and takes its large steps while the kernel is wide);
// residuals beyond max(max_correspondence_distance, three widths) are ignored. Until the kernel
// reaches kernel_width only every coarse_stride-th point takes part, so the re-associations of
// those large steps fit a quarter of the surfaces; the last iterations use every point. The prior (T_prior, sigmas) adds
// Log(T_prior^-1 T)^T P Log(T_prior^-1 T) with P = diag(1/sigma_t^2 x3, 1/sigma_r^2 x3), the
// residuals having unit variance kernel_width^2. With a DeskewCoupling the points also move with
// the twist the estimate implies (a sweep's deskew followed inside the loop).
//
// Failure cases: an empty source, a map without surfaces near the guess (fewer than
// min_correspondences matches), an invalid config or DeskewCoupling; they return an Error that
// says which.

#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/cloud/voxel_hash_map.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"

namespace hanzo::fusion::lidar {

struct SurfaceRegistrationConfig {
  int max_iterations = 30;
  double translation_tolerance = 1e-3;  ///< m: converged when a step is below both
  double rotation_tolerance = 1e-4;     ///< rad
  double max_correspondence_distance = 0.5;  ///< m
  double kernel_width = 0.1;            ///< m
  /// m: the first iteration's kernel width, halved down to kernel_width after each step that
  /// moved the points less than half the width (the gate is max(max_correspondence_distance,
  /// 3 widths)); converged only at kernel_width.
  double initial_kernel_width = 0.5;
  double prior_translation_sigma = 1.0; ///< m; <= 0: no prior
  double prior_rotation_sigma = 0.1;    ///< rad; <= 0: no prior
  std::size_t neighbours = 8;           ///< map points per surface fit (>= 3)
  std::size_t min_neighbours = 5;       ///< fewer found: no residual
  double max_neighbour_distance = 1.0;  ///< m (up to the map's voxel edge is exact)
  double normal_agreement = 0.9;        ///< cosine
  double line_ratio = 0.05;
  double plane_ratio = 0.1;
  double vertical_line_angle = 0.35;    ///< rad
  double reassociation_translation = 0.05;  ///< m
  double reassociation_rotation = 0.005;    ///< rad
  std::size_t min_correspondences = 50;
  /// The iterations before the kernel reaches kernel_width (the large steps of a poor
  /// prediction) use every coarse_stride-th source point only; from then on, all points (a run
  /// that ends at max_iterations before that reports the subset's correspondences). 1: all
  /// points throughout (also when the subset would hold fewer than 1000 points, matches fewer
  /// than min_correspondences, or the kernel starts at kernel_width).
  std::size_t coarse_stride = 4;
  int num_threads = 1;                  ///< <= 0: all cores

  Status validate() const;
};

struct SurfaceRegistrationResult {
  SE3 T_map_source;
  bool converged = false;
  int iterations = 0;
  int associations = 0;  ///< surface fits (1 + re-associations)
  int coarse_iterations = 0;  ///< iterations on the coarse subset (coarse_stride), before all points
  std::size_t correspondences = 0;
  std::size_t plane_correspondences = 0;
  std::size_t line_correspondences = 0;
  double inlier_rmse = 0.0;  ///< m, RMS of the matched residuals at the final estimate
  /// Information of T_map_source from the residuals alone (no prior), tangent order (x, y, z,
  /// rx, ry, rz), scaled by the a-posteriori residual variance (as RegistrationResult's).
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
};

/// A deskew that follows the estimate (constant-twist deskewing without an IMU). Source point i
/// was measured times[i] seconds from the pose's reference time (negative: before it) and was
/// deskewed with the twist the prior's pose implies. The twist is taken to change with the
/// estimate T by G Log(T_prior^-1 T) per second, G = diag(translation_gain x3, rotation_gain x3),
/// so the registration moves point i to Exp(times[i] G Log(T_prior^-1 T)) p_i as T moves (second
/// order in the angle), and a pose step moves it by (1 + gain times[i]) times as much as a rigid
/// point (its Jacobian's translation and rotation halves scaled so: first order, commutators
/// dropped). LidarOdometry's gains are its deskew_*_coupling / interval. A sweep deskewed with
/// the wrong twist then converges to its own motion in one registration instead of crawling
/// between poses that suit no deskew.
/// Errors: times not one per source point, a non-finite gain, |gain times[i]| >= 1.
struct DeskewCoupling {
  std::vector<float> times;     ///< s from the reference time, one per source point
  double translation_gain = 0.0;  ///< 1/s; 0 and rotation_gain 0: the deskew stays as given
  double rotation_gain = 0.0;     ///< 1/s
};

/// Aligns `source` (points in the source frame) to the map's surfaces from `guess`, with the
/// prior centred on `T_prior` (usually the guess itself). `deskew` (optional): the source's
/// deskew follows the estimate (see DeskewCoupling).
Result<SurfaceRegistrationResult> align_to_surfaces(const std::vector<Eigen::Vector3f>& source,
                                                    const cloud::VoxelHashMap& map, const SE3& guess,
                                                    const SE3& T_prior, const SurfaceRegistrationConfig& config = {},
                                                    const DeskewCoupling* deskew = nullptr);

/// Smallest / largest eigenvalue of the translation information of a 6x6 information matrix
/// (order x, y, z, rx, ry, rz) after marginalizing the rotation (Schur complement): near 0 when
/// the translation is unconstrained along some direction. 0 when the information is singular.
double translation_constraint_ratio(const Eigen::Matrix<double, 6, 6>& information);

}  // namespace hanzo::fusion::lidar
