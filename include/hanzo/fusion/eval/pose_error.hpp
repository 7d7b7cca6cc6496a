#pragma once
// Absolute and relative pose errors (APE / RPE), with the definitions of evo
// (github.com/MichaelGrupp/evo, evo/core/metrics.py and filters.py), so numbers computed here
// can be compared with numbers people publish from evo.
//
//  APE_i = T_ref_i^-1 T_est_i;                   the error is a scalar of APE_i by `PoseRelation`
//  RPE_ij = (T_ref_i^-1 T_ref_j)^-1 (T_est_i^-1 T_est_j) over pairs (i, j) chosen by `delta`
//
// Both take associated trajectories (same size, pair i = pose i of each; see association.hpp).

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/eval/alignment.hpp"
#include "hanzo/fusion/eval/statistics.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::eval {

/// Which scalar of the error transform E = [R t] is reported.
enum class PoseRelation {
  kTranslation,       ///< ||t|| (m)                           evo: trans_part
  kRotationAngleDeg,  ///< rotation angle of R (deg)           evo: angle_deg
  kRotationAngleRad,  ///< rotation angle of R (rad)           evo: angle_rad
  kRotationPart,      ///< ||R - I||_F (unitless)              evo: rot_part
  kFull,              ///< ||E - I||_F over the 4x4 matrix     evo: full
};

/// "trans_part", "angle_deg", "angle_rad", "rot_part", "full".
Result<PoseRelation> pose_relation_from_name(const std::string& name);
const char* pose_relation_name(PoseRelation relation);
/// "m", "deg", "rad" or "" (for rot_part and full).
const char* pose_relation_unit(PoseRelation relation);

struct ApeConfig {
  PoseRelation relation = PoseRelation::kTranslation;
  Alignment alignment = Alignment::kNone;
  int align_num_poses = -1;  ///< align on the first N pairs only (<= 0: all)
};

struct ApeResult {
  std::vector<double> errors;   ///< one per pose pair
  ErrorStatistics statistics;
  SimilarityTransform alignment;  ///< applied to the estimate (identity for kNone)
  io::Trajectory reference;
  io::Trajectory estimate_aligned;
};

/// Fails when the trajectories differ in size, are empty, or alignment fails.
Result<ApeResult> compute_ape(const io::Trajectory& reference, const io::Trajectory& estimate, const ApeConfig& config = {});

/// How RPE's `delta` is measured along the trajectory.
enum class DeltaUnit {
  kFrames,   ///< pose index steps
  kMeters,   ///< travelled distance
  kDegrees,  ///< accumulated rotation angle
  kRadians,
};
/// "f" / "frames", "m" / "meters", "deg" / "degrees", "rad" / "radians".
Result<DeltaUnit> delta_unit_from_name(const std::string& name);
const char* delta_unit_name(DeltaUnit unit);

struct RpeConfig {
  PoseRelation relation = PoseRelation::kTranslation;
  double delta = 1.0;
  DeltaUnit delta_unit = DeltaUnit::kFrames;
  /// false (evo's default): consecutive pairs — each pair starts where the previous ended;
  /// true: a pair from every pose to the pose delta further on.
  bool all_pairs = false;
  /// With all_pairs and a distance/angle unit, a pair is kept when its length is within
  /// delta * relative_tolerance of delta (evo's rel_delta_tol, default 0.1).
  double relative_tolerance = 0.1;
  /// Distances and angles for choosing pairs are measured on the estimate (evo's default) or
  /// on the reference.
  bool pairs_from_reference = false;
  Alignment alignment = Alignment::kNone;
  int align_num_poses = -1;
};

struct RpeResult {
  std::vector<double> errors;
  std::vector<std::pair<std::size_t, std::size_t>> pairs;  ///< (i, j) pose indices of each error
  ErrorStatistics statistics;
  SimilarityTransform alignment;
};

/// Fails when the trajectories differ in size, delta is not positive (or not whole for
/// frames), or no pair can be formed ("no pairs for delta 10 m: the trajectory is 8.2 m long").
Result<RpeResult> compute_rpe(const io::Trajectory& reference, const io::Trajectory& estimate, const RpeConfig& config = {});

/// The (i, j) pairs evo's filters choose on `poses` for the given delta (exposed for tests).
std::vector<std::pair<std::size_t, std::size_t>> select_pairs(const io::Trajectory& poses, double delta, DeltaUnit unit,
                                                              bool all_pairs, double relative_tolerance);

/// The scalar error of transform `error` by relation.
double pose_error(const io::PoseMatrix& error, PoseRelation relation);

}  // namespace hanzo::fusion::eval
