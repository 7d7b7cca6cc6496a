#pragma once
// Trajectory alignment before computing errors: the estimate is moved (and scaled) onto the
// reference by least squares over associated positions.
//
// Umeyama, "Least-squares estimation of transformation parameters between two point patterns",
// IEEE TPAMI 13(4), 1991: eqs. (38)-(42) give R = U S V^T, c = tr(D S) / sigma_x^2 and
// t = mu_y - c R mu_x from the SVD of the cross-covariance Sigma_xy = U D V^T.

#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::eval {

enum class Alignment {
  kNone,         ///< compare as given
  kSE3,          ///< rotation + translation (evo -a)
  kSim3,         ///< rotation + translation + scale (evo -as), for monocular estimates
  kScale,        ///< scale only (evo -s)
  kTranslation,  ///< translation only: the position means coincide
  kOrigin,       ///< first poses coincide (evo --align_origin)
  /// rotation about the vertical + translation (4 degrees of freedom): for estimates whose roll
  /// and pitch are observable (an IMU measures gravity), so that a tilted estimate is not
  /// aligned away as with se3 (Zhang and Scaramuzza, IROS 2018, "posyaw")
  kYaw,
};

/// "none", "se3", "sim3", "scale", "translation", "origin", "yaw".
Result<Alignment> alignment_from_name(const std::string& name);
const char* alignment_name(Alignment alignment);

/// p_reference = scale * R * p_estimate + t, i.e. T_reference_estimate with a scale.
struct SimilarityTransform {
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double scale = 1.0;
};

/// Umeyama's least-squares similarity mapping `source` onto `target` (same size, >= 3 points
/// for rotation). With `with_scale` false the scale is 1. Fails when the points are degenerate
/// (fewer than two non-zero singular values of the cross-covariance: all points on a line).
Result<SimilarityTransform> umeyama_alignment(const std::vector<Eigen::Vector3d>& source,
                                              const std::vector<Eigen::Vector3d>& target, bool with_scale);

/// The yaw and translation mapping `source` onto `target` in least squares (z is the vertical).
/// Fails for fewer than 2 pairs or when the horizontal positions do not determine the yaw.
Result<SimilarityTransform> yaw_alignment(const std::vector<Eigen::Vector3d>& source, const std::vector<Eigen::Vector3d>& target);

/// Aligns `estimate` in place onto `reference` (associated: same size) using the first
/// `num_poses` pairs (all when <= 0 or more than there are). Returns the transform applied.
Result<SimilarityTransform> align_trajectory(io::Trajectory& estimate, const io::Trajectory& reference,
                                             Alignment alignment, int num_poses = -1);

}  // namespace hanzo::fusion::eval
