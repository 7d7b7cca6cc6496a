#pragma once
// Timestamp association of a reference and an estimated trajectory, as evo does it
// (evo/core/sync.py): every pose of the trajectory with fewer poses is matched to the pose of
// the other whose time (plus `estimate_time_offset_s` for the estimate) is nearest; pairs
// further apart than `max_time_difference_s` are dropped. A pose of the longer trajectory
// may be matched more than once.

#include <cstddef>
#include <vector>

#include <optional>
#include <string>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::eval {

struct AssociationConfig {
  /// Largest accepted time difference of a pair (s). evo's default (--t_max_diff) is 0.01.
  double max_time_difference_s = 0.01;
  /// Added to every estimate time before matching (s); evo's --t_offset.
  double estimate_time_offset_s = 0.0;
};

struct AssociatedTrajectories {
  io::Trajectory reference;  ///< reference[i] pairs with estimate[i]
  io::Trajectory estimate;
  std::vector<std::size_t> reference_indices;  ///< index of each pair in the input reference
  std::vector<std::size_t> estimate_indices;
};

/// Fails when no pair is found (names the time ranges so an offset or a wrong file is easy to spot).
Result<AssociatedTrajectories> associate(const io::Trajectory& reference, const io::Trajectory& estimate,
                                         const AssociationConfig& config = {});

/// Times below this (s, 1973) are relative ones (a dataset's times from 0), not Unix times.
inline constexpr double kRelativeTimesBelow_s = 1e8;
/// Where the importers place relative times by default (`import kitti|images --time-origin`):
/// 1e9 s, 2001-09-09T01:46:40Z.
inline constexpr double kDefaultRelativeTimeOrigin_s = 1e9;

/// A constant offset between a trajectory in relative times and one in absolute times.
struct TimeOffsetGuess {
  double estimate_time_offset_s = 0.0;  ///< added to the estimate's times (AssociationConfig)
  std::string description;              ///< how the times were paired, one sentence
};

/// When the two time ranges do not overlap and exactly one trajectory starts before
/// kRelativeTimesBelow_s, the offset that pairs them: -/+ kDefaultRelativeTimeOrigin_s when the
/// absolute one lies within [origin, origin + kRelativeTimesBelow_s) (an imported dataset's
/// estimate against the dataset's own ground truth), else the difference of the first times.
/// None otherwise (times overlap, both relative, both absolute, or an empty trajectory).
std::optional<TimeOffsetGuess> guess_relative_time_offset(const io::Trajectory& reference, const io::Trajectory& estimate);

}  // namespace hanzo::fusion::eval
