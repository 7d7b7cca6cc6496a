#pragma once
// Registration of planar laser scans (2D LiDAR): the SE2 transform T_target_source that maps
// source points onto the target (p_target = T_target_source * p_source), by point-to-line ICP
// (Censi, "An ICP variant using a point-to-line metric", ICRA 2008): residual n_t . (q - t) for
// the nearest target point t with the line normal n_t fitted to its neighbours, q the source
// point moved by the current estimate. Gauss-Newton on SE2 with the right perturbation
// T <- T Exp(delta), delta = (x, y, theta) as in core/se2.hpp; correspondences re-searched every
// iteration; Huber weights; coarse-to-fine correspondence gates as in lidar/registration.hpp.
//
// Target points whose neighbourhood is not line-like but dense (clutter, corners, door frames)
// have no normal; a source point matched to one of them gets the point-to-point residual q - t
// instead. Those are what fix the pose along a corridor, whose walls leave it free. Sparse
// points that fit no line are dropped from the target. A planar target is prepared once (kd-tree, normals)
// and matched against any number of sources.
//
// Failure cases (an Error naming which): an empty or non-finite cloud, a target without any
// line-like neighbourhood, fewer than 3 correspondences at the initial guess, an invalid config.
// Not converging within max_iterations is not an error (converged = false).

#include <cstddef>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se2.hpp"

namespace hanzo::fusion::lidar {

/// Points of a planar scan or map, metres, in the frame the caller names.
using PlanarPoints = std::vector<Eigen::Vector2d>;

struct PlanarIcpConfig {
  double max_correspondence_distance = 0.3;                   ///< m, the final gate
  std::vector<double> coarse_correspondence_distances = {1.0};  ///< m, wider gates run first
  int max_iterations = 30;                                    ///< per gate
  double translation_tolerance = 1e-4;                        ///< m; converged when a step is below both
  double rotation_tolerance = 1e-4;                           ///< rad
  double huber_width = 0.05;                                  ///< m of point-to-line distance
  int normal_neighbours = 8;                                  ///< k nearest target points for a line fit (>= 3)
  double normal_radius = 2.0;                                 ///< m; neighbours farther away are not used (sparse far walls still get a line)
  /// A neighbourhood is line-like when its smaller covariance eigenvalue is below this
  /// fraction of the larger one.
  double max_line_eigenvalue_ratio = 0.1;
  /// A target point that fits no line is kept (matched point-to-point) only when its 4 nearest
  /// neighbours lie within this radius (m): corners, poles, clutter; sparse ones are dropped.
  double point_cluster_radius = 0.3;
  /// Standard deviation of a point-to-line residual (m): weighs the points against the prior.
  double point_sigma = 0.05;
  /// A prior on the initial guess (from odometry or an IMU): cost e^T S^-1 e with
  /// e = Log(guess^-1 T) and S = diag(sigma_t^2, sigma_t^2, sigma_r^2). In a corridor the
  /// geometry does not fix the pose along its axis; the prior keeps the guess there instead of
  /// letting ICP slide. 0: no prior.
  double guess_translation_sigma = 0.0;  ///< m
  double guess_rotation_sigma = 0.0;     ///< rad

  /// Ok, or an Error naming the first invalid field.
  Status validate() const;
};

struct PlanarIcpResult {
  SE2 T_target_source;
  bool converged = false;
  int iterations = 0;              ///< over all gates
  size_t num_correspondences = 0;  ///< source points matched within the final gate at the estimate
  double fitness = 0.0;            ///< num_correspondences / source points, in [0, 1]
  double inlier_rmse = 0.0;        ///< m, RMS residual (point-to-line or point-to-point) of the matched points
  /// Information of T_target_source in the tangent (x, y, theta), right perturbation: the
  /// points' Gauss-Newton Hessian divided by their a-posteriori residual variance (optimistic:
  /// the correspondences are treated as independent), plus the prior's information.
  Eigen::Matrix3d information = Eigen::Matrix3d::Zero();
  /// Eigenvalues of the points' Hessian (without the prior), ascending: a first value far below the others is a direction
  /// the scene does not constrain (a corridor along its axis). Mixed units (m^-2 and rad^-2).
  Eigen::Vector3d hessian_eigenvalues = Eigen::Vector3d::Zero();
};

/// A target prepared for point-to-line matching: kd-tree and line normals.
class PlanarTarget {
 public:
  static Result<PlanarTarget> create(PlanarPoints points, const PlanarIcpConfig& config = {});
  ~PlanarTarget();
  PlanarTarget(PlanarTarget&&) noexcept;
  PlanarTarget& operator=(PlanarTarget&&) noexcept;

  /// The target points kept (line-like or in dense clusters).
  const PlanarPoints& points() const;
  /// Unit normal of each point, zero where the neighbourhood is not line-like.
  const std::vector<Eigen::Vector2d>& normals() const;
  /// Index of the nearest point within sqrt(max_squared_distance), or -1.
  long nearest(const Eigen::Vector2d& query, double max_squared_distance, double* squared_distance) const;

 private:
  struct Impl;
  explicit PlanarTarget(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// How well a match's information constrains the translation in its weakest direction: the
/// smaller / larger eigenvalue of the translation's marginal information (the Schur
/// complement of the rotation), in [0, 1]. Near 0 in a corridor (the walls leave the axis
/// free); `weak_direction` (optional) receives the unit direction (target frame is the
/// estimate's body frame: the tangent's x, y). 0 for an information without translation.
double translation_constraint_ratio(const Eigen::Matrix3d& information, Eigen::Vector2d* weak_direction = nullptr);

/// Aligns `source` to `target` from `T_target_source_guess`.
Result<PlanarIcpResult> align_planar(const PlanarPoints& source, const PlanarTarget& target, const SE2& T_target_source_guess,
                                     const PlanarIcpConfig& config = {});

}  // namespace hanzo::fusion::lidar
