#pragma once
// Timestamp association of a reference and an estimated trajectory, as evo does it
// (evo/core/sync.py): every pose of the trajectory with fewer poses is matched to the pose of
// the other whose time (plus `estimate_time_offset_s` for the estimate) is nearest; pairs
// further apart than `max_time_difference_s` are dropped. A pose of the longer trajectory
// may be matched more than once.

#include <cstddef>
#include <vector>

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

}  // namespace hanzo::fusion::eval
