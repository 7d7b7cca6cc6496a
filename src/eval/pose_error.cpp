#include "hanzo/fusion/eval/pose_error.hpp"

#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/core/so3.hpp"

namespace hanzo::fusion::eval {
namespace {

constexpr PoseRelation kAllRelations[] = {PoseRelation::kTranslation, PoseRelation::kRotationAngleDeg,
                                          PoseRelation::kRotationAngleRad, PoseRelation::kRotationPart,
                                          PoseRelation::kFull};

// Inverse of a rigid transform [R t] as [R^T, -R^T t] (what evo's lie.se3_inverse computes;
// it matters for rotation matrices that are orthonormal only to the printed digits).
io::PoseMatrix rigid_inverse(const io::PoseMatrix& T) {
  io::PoseMatrix inverse = io::PoseMatrix::Identity();
  inverse.block<3, 3>(0, 0) = T.block<3, 3>(0, 0).transpose();
  inverse.block<3, 1>(0, 3) = -T.block<3, 3>(0, 0).transpose() * T.block<3, 1>(0, 3);
  return inverse;
}

double rotation_angle(const Eigen::Matrix3d& rotation) { return SO3::from_matrix(rotation).angle(); }

Status check_same_size(const io::Trajectory& reference, const io::Trajectory& estimate) {
  if (reference.empty()) return Error("the reference trajectory is empty");
  if (reference.size() != estimate.size()) {
    return Error(fmt::format("reference and estimate must be associated (same number of poses): {} vs {}",
                             reference.size(), estimate.size()));
  }
  return ok_status();
}

// The step "length" between two consecutive poses in the unit pairs are chosen by.
double step_amount(const io::PoseMatrix& from, const io::PoseMatrix& to, DeltaUnit unit) {
  if (unit == DeltaUnit::kMeters) return (to.block<3, 1>(0, 3) - from.block<3, 1>(0, 3)).norm();
  const double angle = rotation_angle(from.block<3, 3>(0, 0).transpose() * to.block<3, 3>(0, 0));
  return unit == DeltaUnit::kDegrees ? angle * 180.0 / M_PI : angle;
}

}  // namespace

Result<PoseRelation> pose_relation_from_name(const std::string& name) {
  for (PoseRelation relation : kAllRelations) {
    if (name == pose_relation_name(relation)) return relation;
  }
  return Error(fmt::format("unknown pose relation '{}' (expected trans_part, angle_deg, angle_rad, rot_part or full)", name));
}

const char* pose_relation_name(PoseRelation relation) {
  switch (relation) {
    case PoseRelation::kTranslation: return "trans_part";
    case PoseRelation::kRotationAngleDeg: return "angle_deg";
    case PoseRelation::kRotationAngleRad: return "angle_rad";
    case PoseRelation::kRotationPart: return "rot_part";
    case PoseRelation::kFull: return "full";
  }
  return "?";
}

const char* pose_relation_unit(PoseRelation relation) {
  switch (relation) {
    case PoseRelation::kTranslation: return "m";
    case PoseRelation::kRotationAngleDeg: return "deg";
    case PoseRelation::kRotationAngleRad: return "rad";
    default: return "";
  }
}

Result<DeltaUnit> delta_unit_from_name(const std::string& name) {
  if (name == "f" || name == "frames") return DeltaUnit::kFrames;
  if (name == "m" || name == "meters") return DeltaUnit::kMeters;
  if (name == "deg" || name == "degrees") return DeltaUnit::kDegrees;
  if (name == "rad" || name == "radians") return DeltaUnit::kRadians;
  return Error(fmt::format("unknown delta unit '{}' (expected f, m, deg or rad)", name));
}

const char* delta_unit_name(DeltaUnit unit) {
  switch (unit) {
    case DeltaUnit::kFrames: return "frames";
    case DeltaUnit::kMeters: return "m";
    case DeltaUnit::kDegrees: return "deg";
    case DeltaUnit::kRadians: return "rad";
  }
  return "?";
}

double pose_error(const io::PoseMatrix& error, PoseRelation relation) {
  switch (relation) {
    case PoseRelation::kTranslation: return error.block<3, 1>(0, 3).norm();
    case PoseRelation::kRotationAngleRad: return rotation_angle(error.block<3, 3>(0, 0));
    case PoseRelation::kRotationAngleDeg: return rotation_angle(error.block<3, 3>(0, 0)) * 180.0 / M_PI;
    case PoseRelation::kRotationPart: return (error.block<3, 3>(0, 0) - Eigen::Matrix3d::Identity()).norm();
    case PoseRelation::kFull: return (error - io::PoseMatrix::Identity()).norm();
  }
  return 0.0;
}

Result<ApeResult> compute_ape(const io::Trajectory& reference, const io::Trajectory& estimate, const ApeConfig& config) {
  HANZO_RETURN_IF_ERROR(check_same_size(reference, estimate));
  ApeResult result;
  result.reference = reference;
  result.estimate_aligned = estimate;
  HANZO_ASSIGN_OR_RETURN(result.alignment, align_trajectory(result.estimate_aligned, reference, config.alignment,
                                                            config.align_num_poses));
  result.errors.reserve(reference.size());
  for (std::size_t i = 0; i < reference.size(); ++i) {
    if (config.relation == PoseRelation::kTranslation) {  // positions only, as evo does
      result.errors.push_back((result.estimate_aligned.position(i) - reference.position(i)).norm());
    } else {
      const io::PoseMatrix error = rigid_inverse(reference.poses[i]) * result.estimate_aligned.poses[i];
      result.errors.push_back(pose_error(error, config.relation));
    }
  }
  result.statistics = compute_statistics(result.errors);
  return result;
}

std::vector<std::pair<std::size_t, std::size_t>> select_pairs(const io::Trajectory& poses, double delta, DeltaUnit unit,
                                                              bool all_pairs, double relative_tolerance) {
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  const std::size_t n = poses.size();
  if (unit == DeltaUnit::kFrames) {
    const auto step = static_cast<std::size_t>(delta);
    if (all_pairs) {
      for (std::size_t i = 0; i + step < n; ++i) pairs.emplace_back(i, i + step);
    } else {
      for (std::size_t i = 0; i + step < n; i += step) pairs.emplace_back(i, i + step);
    }
    return pairs;
  }
  if (all_pairs) {
    // Accumulated amount from the start; for every i the j > i whose accumulated difference is
    // nearest to delta, kept when within the tolerance (evo filters.py, all_pairs branch).
    std::vector<double> accumulated(n, 0.0);
    for (std::size_t i = 1; i < n; ++i) accumulated[i] = accumulated[i - 1] + step_amount(poses.poses[i - 1], poses.poses[i], unit);
    const double tolerance = delta * relative_tolerance;
    for (std::size_t i = 0; i + 1 < n; ++i) {
      std::size_t best = i + 1;
      double best_difference = std::abs(accumulated[best] - accumulated[i] - delta);
      for (std::size_t j = i + 2; j < n; ++j) {
        const double difference = std::abs(accumulated[j] - accumulated[i] - delta);
        if (difference < best_difference) {
          best = j;
          best_difference = difference;
        }
        if (accumulated[j] - accumulated[i] > delta + tolerance) break;  // further j only grow
      }
      if (best_difference <= tolerance) pairs.emplace_back(i, best);
    }
    return pairs;
  }
  // Consecutive: walk the poses summing steps; each time the sum reaches delta record the index
  // and restart the sum; pairs join consecutive recorded indices.
  std::vector<std::size_t> marks;
  double current = 0.0;
  for (std::size_t i = 1; i < n; ++i) {
    current += step_amount(poses.poses[i - 1], poses.poses[i], unit);
    if (current >= delta) {
      marks.push_back(i);
      current = 0.0;
    }
  }
  for (std::size_t k = 1; k < marks.size(); ++k) pairs.emplace_back(marks[k - 1], marks[k]);
  return pairs;
}

Result<RpeResult> compute_rpe(const io::Trajectory& reference, const io::Trajectory& estimate, const RpeConfig& config) {
  HANZO_RETURN_IF_ERROR(check_same_size(reference, estimate));
  if (!(config.delta > 0.0) || !std::isfinite(config.delta)) {
    return Error(fmt::format("RPE delta must be a positive number, got {}", config.delta));
  }
  if (config.delta_unit == DeltaUnit::kFrames && config.delta != std::floor(config.delta)) {
    return Error(fmt::format("RPE delta in frames must be a whole number, got {}", config.delta));
  }
  RpeResult result;
  io::Trajectory aligned = estimate;
  HANZO_ASSIGN_OR_RETURN(result.alignment, align_trajectory(aligned, reference, config.alignment, config.align_num_poses));
  result.pairs = select_pairs(config.pairs_from_reference ? reference : aligned, config.delta, config.delta_unit,
                              config.all_pairs, config.relative_tolerance);
  if (result.pairs.empty()) {
    return Error(fmt::format("RPE: no pose pairs {} {} apart in a trajectory of {} poses and {:.3f} m", config.delta,
                             delta_unit_name(config.delta_unit), reference.size(), reference.path_length()));
  }
  result.errors.reserve(result.pairs.size());
  for (const auto& [i, j] : result.pairs) {
    const io::PoseMatrix reference_motion = rigid_inverse(reference.poses[i]) * reference.poses[j];
    const io::PoseMatrix estimate_motion = rigid_inverse(aligned.poses[i]) * aligned.poses[j];
    result.errors.push_back(pose_error(rigid_inverse(reference_motion) * estimate_motion, config.relation));
  }
  result.statistics = compute_statistics(result.errors);
  return result;
}

}  // namespace hanzo::fusion::eval
