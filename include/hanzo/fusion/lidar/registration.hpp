#pragma once
// Rigid registration of two point clouds: the transform T_target_source that maps source points
// onto the target (p_target = T_target_source * p_source).
//
// Methods (all Gauss-Newton on SE3 with the right perturbation T <- T Exp(delta), delta =
// (rho, phi) as in core/se3.hpp, correspondences re-searched every iteration):
// - kPointToPoint: ICP (Besl & McKay 1992), residual q - t for the nearest target point t.
// - kPointToPlane: Chen & Medioni 1992, residual n_t . (q - t) with the target normal n_t.
// - kGicp (the default, per the spec): Generalized-ICP (Segal, Haehnel, Thrun 2009, eq. 2),
//   residual q - t weighted by (C_t + R C_s R^T)^-1 with the plane-regularized covariances of
//   cloud/local_geometry.hpp.
// - kNdt: point-to-distribution NDT (Magnusson 2009, thesis eqs. 6.8-6.10): the target is
//   a grid of Gaussians (one per voxel of `ndt.resolution` holding >= ndt.min_points_per_cell
//   points); each source point scores -d1 exp(-d2/2 x^T S^-1 x) against the cell that holds it
//   and its 6 face neighbours. Minimized by iteratively reweighted Gauss-Newton (each
//   residual weighted by its score's slope), which drops the negative-curvature terms of the
//   exact Newton Hessian and so always steps downhill. Coarse-to-fine over ndt.coarse_levels
//   grids; the result's iterations count all levels.
//
// Robust kernels reweight each correspondence by its residual norm (m for ICP and
// point-to-plane, Mahalanobis units for GICP and NDT). Correspondences farther than
// max_correspondence_distance are ignored.
//
// Failure cases: empty clouds, fewer than 6 correspondences at the initial guess (the guess is
// too far off or the clouds do not overlap), a target prepared for another method, an invalid
// config. They return an Error that says which. Not converging within max_iterations is not an
// error: the result says converged = false and carries the last estimate.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/cloud/kdtree.hpp"
#include "hanzo/fusion/cloud/local_geometry.hpp"
#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"

namespace hanzo::fusion::lidar {

enum class RegistrationMethod { kPointToPoint, kPointToPlane, kGicp, kNdt };
/// "icp", "icp-plane", "gicp", "ndt" (the CLI's --method names).
std::string_view to_string(RegistrationMethod method);
std::optional<RegistrationMethod> registration_method_from_string(std::string_view name);

enum class RobustKernel { kNone, kHuber, kCauchy, kGemanMcClure };
std::string_view to_string(RobustKernel kernel);
std::optional<RobustKernel> robust_kernel_from_string(std::string_view name);

struct NdtConfig {
  double resolution = 1.0;         // m, cell edge of the finest grid
  /// Coarser grids aligned first, each twice the previous cell edge (Magnusson 2009, sec. 6.3.2):
  /// widens the basin of convergence to about the coarsest cell size. 0: the finest grid only.
  int coarse_levels = 2;
  int min_points_per_cell = 6;     // cells with fewer points hold no Gaussian (PCL uses 6)
  double outlier_ratio = 0.55;     // Magnusson's p_o: probability mass of outliers (eq. 6.7)
};

struct RegistrationConfig {
  RegistrationMethod method = RegistrationMethod::kGicp;
  double max_correspondence_distance = 1.0;  // m
  /// Coarse-to-fine gating: registrations with these (larger) distances run first, each
  /// starting from the previous estimate, before the final one with max_correspondence_distance.
  /// A wide gate widens the basin of convergence, the final tight gate removes the bias of far
  /// outliers (point-to-point ICP needs both). Empty by default. Not used by NDT.
  std::vector<double> coarse_correspondence_distances;
  int max_iterations = 32;
  /// Converged when an iteration's step is below both tolerances.
  double translation_tolerance = 1e-4;       // m
  double rotation_tolerance = 1e-4;          // rad
  RobustKernel kernel = RobustKernel::kNone;
  double kernel_width = 1.0;                 // residual-norm scale of the kernel (units above)
  /// Neighbourhoods for GICP covariances and point-to-plane normals, when the clouds lack them.
  cloud::LocalGeometryConfig geometry;
  NdtConfig ndt;
  int num_threads = 1;                       // <= 0: every hardware thread

  /// Ok, or an Error naming the first invalid field ("max_correspondence_distance: -1 <= 0").
  Status validate() const;
};

struct RegistrationResult {
  SE3 T_target_source;
  bool converged = false;
  int iterations = 0;
  size_t num_correspondences = 0;  // source points matched at the final estimate
  double fitness = 0.0;            // num_correspondences / source points, in [0, 1]
  double inlier_rmse = 0.0;        // m, RMS distance of matched points to their target points
  double final_cost = 0.0;         // the method's cost at the final estimate (after kernels)
  /// Information (inverse covariance) of T_target_source in the tangent space, order (x, y, z,
  /// rx, ry, rz), right perturbation: the Gauss-Newton Hessian J^T W J at the final estimate
  /// divided by the a-posteriori residual variance final_cost / (num_correspondences - 6).
  /// Treats correspondences as independent, so it is optimistic on dense clouds.
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
  /// Eigenvalues of the Hessian in ascending order: a small first value relative to the last
  /// means a direction the geometry does not constrain (a corridor along its axis).
  Eigen::Matrix<double, 6, 1> hessian_eigenvalues = Eigen::Matrix<double, 6, 1>::Zero();
};

/// A target cloud prepared once for a method (kd-tree; covariances or normals computed when the
/// cloud lacks them; the NDT grid) and reused for any number of sources. When it computes them,
/// it keeps each point's neighbours (44 bytes a point with the default 10): after the first
/// iteration most correspondences are then updated from the previous one's neighbours instead of
/// a kd-tree search (same nearest neighbours, 7-8 % of GICP's time on the real pair).
class RegistrationTarget {
 public:
  /// Fails on an empty or invalid cloud or an invalid config.
  static Result<RegistrationTarget> create(cloud::PointCloud cloud, const RegistrationConfig& config = {});
  ~RegistrationTarget();
  RegistrationTarget(RegistrationTarget&&) noexcept;
  RegistrationTarget& operator=(RegistrationTarget&&) noexcept;

  RegistrationMethod method() const;
  const cloud::PointCloud& cloud() const;

  struct Impl;
  const Impl& impl() const { return *impl_; }

 private:
  explicit RegistrationTarget(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// Aligns `source` to a prepared target starting from `T_target_source_guess`. config.method
/// must be the method the target was prepared for.
Result<RegistrationResult> align(const cloud::PointCloud& source, const RegistrationTarget& target,
                                 const SE3& T_target_source_guess, const RegistrationConfig& config = {});

/// Prepares `target` and aligns `source` to it (one-off registration of a pair).
Result<RegistrationResult> register_clouds(const cloud::PointCloud& source, const cloud::PointCloud& target,
                                           const SE3& T_target_source_guess, const RegistrationConfig& config = {});

}  // namespace hanzo::fusion::lidar
