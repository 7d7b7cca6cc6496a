#include "pose_refinement.hpp"

#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <opencv2/calib3d.hpp>

namespace hanzo::fusion::vision {

double reprojection_chi2(const SE3& T_camera_world, const PoseObservation& observation, const PinholeCamera& camera) {
  const std::optional<Eigen::Vector2d> pixel = camera.project(T_camera_world.act(observation.point_world));
  if (!pixel) return std::numeric_limits<double>::infinity();
  return (*pixel - observation.pixel).squaredNorm() / (observation.sigma_px * observation.sigma_px);
}

PoseRefinement refine_pose(const SE3& T_camera_world, const std::vector<PoseObservation>& observations, const PinholeCamera& camera,
                           int rounds, int iterations_per_round) {
  PoseRefinement result{T_camera_world, std::vector<bool>(observations.size(), true), static_cast<int>(observations.size())};
  const double huber = std::sqrt(kChi2Pixel95);
  for (int round = 0; round < rounds; ++round) {
    for (int iteration = 0; iteration < iterations_per_round; ++iteration) {
      Eigen::Matrix<double, 6, 6> hessian = Eigen::Matrix<double, 6, 6>::Zero();
      Eigen::Matrix<double, 6, 1> gradient = Eigen::Matrix<double, 6, 1>::Zero();
      int used = 0;
      for (std::size_t i = 0; i < observations.size(); ++i) {
        if (!result.inlier[i]) continue;
        const PoseObservation& observation = observations[i];
        const Eigen::Vector3d p_camera = result.T_camera_world.act(observation.point_world);
        Eigen::Matrix<double, 2, 3> projection_jacobian;
        const std::optional<Eigen::Vector2d> pixel = camera.project(p_camera, &projection_jacobian);
        if (!pixel) continue;
        const Eigen::Vector2d residual = (*pixel - observation.pixel) / observation.sigma_px;
        Eigen::Matrix<double, 3, 6> point_jacobian;
        point_jacobian << Eigen::Matrix3d::Identity(), -SO3::hat(p_camera);
        const Eigen::Matrix<double, 2, 6> jacobian = projection_jacobian * point_jacobian / observation.sigma_px;
        const double norm = residual.norm();
        const double weight = norm <= huber ? 1.0 : huber / norm;
        hessian += weight * jacobian.transpose() * jacobian;
        gradient += weight * jacobian.transpose() * residual;
        ++used;
      }
      if (used < 3) break;
      const Eigen::Matrix<double, 6, 1> step = -hessian.ldlt().solve(gradient);
      if (!step.allFinite()) break;
      result.T_camera_world = SE3::exp(step) * result.T_camera_world;
      if (step.norm() < 1e-8) break;
    }
    result.inliers = 0;
    for (std::size_t i = 0; i < observations.size(); ++i) {
      result.inlier[i] = reprojection_chi2(result.T_camera_world, observations[i], camera) <= kChi2Pixel95;
      result.inliers += result.inlier[i];
    }
  }
  return result;
}

std::optional<PnpSolution> solve_pnp_ransac(const std::vector<cv::Point3d>& points_world, const std::vector<cv::Point2d>& normalized, double threshold,
                                            int iterations) {
  if (points_world.size() < 4 || points_world.size() != normalized.size()) return std::nullopt;
  cv::Mat rotation_vector, translation;
  PnpSolution solution;
  if (!cv::solvePnPRansac(points_world, normalized, cv::Mat::eye(3, 3, CV_64F), cv::noArray(), rotation_vector, translation, false, iterations,
                          static_cast<float>(threshold), 0.999, solution.inliers, cv::SOLVEPNP_EPNP)) {
    return std::nullopt;
  }
  cv::Mat rotation;
  cv::Rodrigues(rotation_vector, rotation);
  Eigen::Matrix3d R;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R(r, c) = rotation.at<double>(r, c);
  }
  solution.T_camera_world = SE3(SO3::from_matrix(R), Eigen::Vector3d(translation.at<double>(0), translation.at<double>(1), translation.at<double>(2)));
  return solution;
}

}  // namespace hanzo::fusion::vision
