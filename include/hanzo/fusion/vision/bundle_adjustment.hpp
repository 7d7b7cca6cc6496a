#pragma once
// Bundle adjustment of a window of camera poses and the points they observe: a dedicated
// Levenberg-Marquardt solver that eliminates the points by the Schur complement (Triggs et al.,
// "Bundle Adjustment - A Modern Synthesis", 2000, section 6.1; Engels, Stewenius and Nister,
// "Bundle Adjustment Rules", 2006). A window of a few tens of poses and thousands of points:
// the reduced camera system is dense (6 x free poses square) and solved by Cholesky (LDLT); each
// point's 3 x 3 block is inverted on its own.
//
// Problem: minimise 0.5 sum_i rho(|r_i|^2) over the free poses and every point, with
//   r_i = (project(T_body_camera_c^-1 T_world_body_k^-1 p_world_j) - pixel_i) / sigma_i
// for observation i of point j from pose k through camera c (pixels; project() is the pinhole
// camera with its distortion), rho the Huber kernel of threshold huber_threshold (whitened
// units): rho(s) = s for s <= delta^2, 2 delta sqrt(s) - delta^2 beyond.
// Perturbation: T_world_body <- T_world_body exp(delta), delta = (rho, phi) (se3.hpp), so
//   d p_body / d delta = [-I, [p_body]x],  d p_body / d p_world = R_world_body^T.
// The robust kernel enters as iteratively reweighted least squares (weights rho'(s)), as Ceres
// does for kernels with rho'' <= 0 (Huber).
// Levenberg-Marquardt as Ceres' trust-region solver runs it (Jacobi column scaling from the
// first iteration, damping diag(J^T J) / radius with the scaled diagonal at least 1e-6, the step
// taken when the cost falls by at least 1e-3 of the linear model's prediction, the radius grown
// by 1 / max(1/3, 1 - (2 rho - 1)^3) and cut by 2, 4, 8, ... in a row), so that a window
// solved here converges to the minimum the graph module's general solver finds.
//
// Failure (returned, the problem's values untouched): an observation naming a pose, point or
// camera that is not there, a sigma that is not positive and finite, a non-finite pixel or
// value, a configuration out of range, a point behind its camera at the start. A step that
// would put a point behind a camera is not taken (the radius shrinks).

#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"

namespace hanzo::fusion::vision {

struct BundleAdjustmentConfig {
  /// Iterations, the steps refused included (Ceres' max_num_iterations).
  int max_iterations = 10;
  /// Huber threshold on the whitened residual's norm: sqrt(5.991), the chi-square 95 % bound
  /// of two degrees of freedom.
  double huber_threshold = 2.447651936;
  /// Levenberg-Marquardt's first trust-region radius (large: the first step is Gauss-Newton's).
  double initial_trust_region_radius = 1e8;
  /// Converged when a step changes the cost by at most this share of it.
  double function_tolerance = 1e-6;
  /// Converged when the step's norm is at most this times (the values' norm + this).
  double parameter_tolerance = 1e-12;
};

/// A camera of the rig: its model and where it sits on the body whose poses are adjusted.
struct BundleCamera {
  PinholeCamera camera;
  SE3 T_body_camera;
};

struct BundleObservation {
  int pose = 0;    ///< index into BundleProblem::T_world_body
  int point = 0;   ///< index into BundleProblem::points_world
  int camera = 0;  ///< index into BundleProblem::cameras
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
  double sigma_px = 1.0;  ///< the pixel's standard deviation
};

struct BundleProblem {
  std::vector<SE3> T_world_body;
  std::vector<bool> pose_fixed;  ///< one per pose; fixed poses are held (the gauge)
  std::vector<Eigen::Vector3d> points_world;
  std::vector<BundleCamera> cameras;
  std::vector<BundleObservation> observations;
};

struct BundleAdjustmentSummary {
  double initial_cost = 0.0;  ///< 0.5 sum rho(|r|^2) at the start
  double final_cost = 0.0;
  int iterations = 0;         ///< steps tried
  int successful_steps = 0;
  bool converged = false;     ///< a tolerance was met before max_iterations
};

/// Checks every field; the error names the first one out of range.
Status validate(const BundleAdjustmentConfig& config);

/// Adjusts problem.T_world_body (the free ones) and problem.points_world in place.
Result<BundleAdjustmentSummary> bundle_adjust(BundleProblem& problem, const BundleAdjustmentConfig& config = {});

/// The whitened residual of one observation and its Jacobians with respect to the pose's
/// perturbation (2 x 6) and the point (2 x 3); false when the point is at or behind the
/// camera's min_depth. Exposed for the numerical Jacobian check.
bool bundle_residual(const SE3& T_world_body, const Eigen::Vector3d& p_world, const BundleCamera& camera, const BundleObservation& observation,
                     Eigen::Vector2d& residual, Eigen::Matrix<double, 2, 6>* d_pose, Eigen::Matrix<double, 2, 3>* d_point);

}  // namespace hanzo::fusion::vision
