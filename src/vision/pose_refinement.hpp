#pragma once
// Pose-only refinement from 2D-3D matches: Gauss-Newton on the whitened reprojection errors
// with a Huber kernel (delta = sqrt(5.991)), in rounds; after each round the observations over
// the chi-square 95 % bound (2 degrees of freedom: 5.991) are set aside and the next round
// starts from the refined pose (ORB-SLAM's Optimizer::PoseOptimization scheme).
// Perturbation: T_camera_world <- exp(delta) T_camera_world, delta = (rho, phi):
//   d p_camera / d delta = [I, -[p_camera]x].

#include <optional>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/core/se3.hpp"

namespace hanzo::fusion::vision {

struct PoseObservation {
  Eigen::Vector3d point_world;
  Eigen::Vector2d pixel;
  double sigma_px = 1.0;
};

struct PoseRefinement {
  SE3 T_camera_world;
  std::vector<bool> inlier;  ///< per observation, after the last round
  int inliers = 0;
};

PoseRefinement refine_pose(const SE3& T_camera_world, const std::vector<PoseObservation>& observations, const PinholeCamera& camera,
                           int rounds = 4, int iterations_per_round = 10);

/// Squared whitened reprojection error of one observation (infinity behind the camera).
double reprojection_chi2(const SE3& T_camera_world, const PoseObservation& observation, const PinholeCamera& camera);

struct PnpSolution {
  SE3 T_camera_world;
  std::vector<int> inliers;  ///< indices into the correspondences
};

/// T_camera_world from 3D points (world frame) and their undistorted normalized image
/// coordinates by EPnP inside RANSAC (OpenCV's solvePnPRansac, 99.9 % confidence); inliers within
/// `threshold` (normalized units: pixels / fx). None when fewer than 4 correspondences or it fails.
std::optional<PnpSolution> solve_pnp_ransac(const std::vector<cv::Point3d>& points_world, const std::vector<cv::Point2d>& normalized, double threshold,
                                            int iterations);

/// The chi-square 95 % bound of a 2D pixel residual.
inline constexpr double kChi2Pixel95 = 5.991;

}  // namespace hanzo::fusion::vision
