#include "hanzo/fusion/eval/alignment.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <fmt/format.h>

namespace hanzo::fusion::eval {

Result<Alignment> alignment_from_name(const std::string& name) {
  for (Alignment a : {Alignment::kNone, Alignment::kSE3, Alignment::kSim3, Alignment::kScale, Alignment::kTranslation,
                      Alignment::kOrigin, Alignment::kYaw}) {
    if (name == alignment_name(a)) return a;
  }
  return Error(fmt::format("unknown alignment '{}' (expected none, se3, sim3, scale, translation, origin or yaw)", name));
}

const char* alignment_name(Alignment alignment) {
  switch (alignment) {
    case Alignment::kNone: return "none";
    case Alignment::kSE3: return "se3";
    case Alignment::kSim3: return "sim3";
    case Alignment::kScale: return "scale";
    case Alignment::kTranslation: return "translation";
    case Alignment::kOrigin: return "origin";
    case Alignment::kYaw: return "yaw";
  }
  return "?";
}

Result<SimilarityTransform> umeyama_alignment(const std::vector<Eigen::Vector3d>& source,
                                              const std::vector<Eigen::Vector3d>& target, bool with_scale) {
  if (source.size() != target.size()) {
    return Error(fmt::format("alignment needs as many source as target points ({} vs {})", source.size(), target.size()));
  }
  if (source.size() < 2) return Error(fmt::format("alignment needs at least 2 point pairs, got {}", source.size()));
  const auto n = static_cast<double>(source.size());
  Eigen::Vector3d mean_source = Eigen::Vector3d::Zero();
  Eigen::Vector3d mean_target = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < source.size(); ++i) {
    mean_source += source[i];
    mean_target += target[i];
  }
  mean_source /= n;
  mean_target /= n;
  double variance_source = 0.0;  // sigma_x^2, eq. (36)
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // Sigma_xy, eq. (38)
  for (std::size_t i = 0; i < source.size(); ++i) {
    const Eigen::Vector3d x = source[i] - mean_source;
    variance_source += x.squaredNorm();
    covariance += (target[i] - mean_target) * x.transpose();
  }
  variance_source /= n;
  covariance /= n;
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(covariance, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d singular_values = svd.singularValues();
  const auto nonzero = (singular_values.array() > std::numeric_limits<double>::epsilon()).count();
  if (nonzero < 2) {
    return Error("alignment is degenerate: the positions lie on a line or a point (rotation is not determined)");
  }
  Eigen::Matrix3d s = Eigen::Matrix3d::Identity();  // eq. (39): reflection guard
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) s(2, 2) = -1.0;
  SimilarityTransform out;
  out.rotation = svd.matrixU() * s * svd.matrixV().transpose();                          // eq. (40)
  out.scale = with_scale ? (singular_values.asDiagonal() * s).trace() / variance_source : 1.0;  // eq. (42)
  out.translation = mean_target - out.scale * out.rotation * mean_source;               // eq. (41)
  return out;
}

Result<SimilarityTransform> yaw_alignment(const std::vector<Eigen::Vector3d>& source, const std::vector<Eigen::Vector3d>& target) {
  if (source.size() != target.size() || source.size() < 2) {
    return Error(fmt::format("yaw alignment needs at least 2 point pairs, as many sources as targets ({} vs {})", source.size(), target.size()));
  }
  Eigen::Vector3d mean_source = Eigen::Vector3d::Zero();
  Eigen::Vector3d mean_target = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < source.size(); ++i) {
    mean_source += source[i];
    mean_target += target[i];
  }
  mean_source /= static_cast<double>(source.size());
  mean_target /= static_cast<double>(source.size());
  // The yaw minimizing sum |y - R_z x|^2 over centred points: atan2(sum (x cross y)_z, sum x.y) horizontally.
  double sine = 0.0;
  double cosine = 0.0;
  for (std::size_t i = 0; i < source.size(); ++i) {
    const Eigen::Vector3d x = source[i] - mean_source;
    const Eigen::Vector3d y = target[i] - mean_target;
    sine += x.x() * y.y() - x.y() * y.x();
    cosine += x.x() * y.x() + x.y() * y.y();
  }
  if (std::hypot(sine, cosine) <= std::numeric_limits<double>::epsilon()) {
    return Error("yaw alignment is degenerate: the horizontal positions are all at one point");
  }
  SimilarityTransform out;
  out.rotation = Eigen::AngleAxisd(std::atan2(sine, cosine), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  out.translation = mean_target - out.rotation * mean_source;
  return out;
}

Result<SimilarityTransform> align_trajectory(io::Trajectory& estimate, const io::Trajectory& reference,
                                             Alignment alignment, int num_poses) {
  if (estimate.size() != reference.size()) {
    return Error(fmt::format("alignment needs associated trajectories of equal size ({} vs {} poses)",
                             estimate.size(), reference.size()));
  }
  if (estimate.empty()) return Error("cannot align an empty trajectory");
  const std::size_t count =
      num_poses <= 0 ? estimate.size() : std::min(estimate.size(), static_cast<std::size_t>(num_poses));
  SimilarityTransform transform;
  if (alignment == Alignment::kNone) return transform;
  if (alignment == Alignment::kOrigin) {
    const io::PoseMatrix T = reference.poses[0] * estimate.poses[0].inverse();
    transform.rotation = T.block<3, 3>(0, 0);
    transform.translation = T.block<3, 1>(0, 3);
  } else if (alignment == Alignment::kTranslation) {
    Eigen::Vector3d offset = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < count; ++i) offset += reference.position(i) - estimate.position(i);
    transform.translation = offset / static_cast<double>(count);
  } else {
    std::vector<Eigen::Vector3d> source(count);
    std::vector<Eigen::Vector3d> target(count);
    for (std::size_t i = 0; i < count; ++i) {
      source[i] = estimate.position(i);
      target[i] = reference.position(i);
    }
    const bool with_scale = alignment == Alignment::kSim3 || alignment == Alignment::kScale;
    if (alignment == Alignment::kYaw) {
      HANZO_ASSIGN_OR_RETURN(transform, yaw_alignment(source, target));
    } else {
      HANZO_ASSIGN_OR_RETURN(transform, umeyama_alignment(source, target, with_scale));
    }
    if (alignment == Alignment::kScale) {  // keep only the scale, as evo -s does
      transform.rotation.setIdentity();
      transform.translation.setZero();
    }
  }
  io::PoseMatrix T = io::PoseMatrix::Identity();
  T.block<3, 3>(0, 0) = transform.rotation;
  T.block<3, 1>(0, 3) = transform.translation;
  estimate.transform(T, transform.scale);
  return transform;
}

}  // namespace hanzo::fusion::eval
