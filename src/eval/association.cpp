#include "hanzo/fusion/eval/association.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <fmt/format.h>

namespace hanzo::fusion::eval {
namespace {

// Index of the time in sorted `times` nearest to `query` (the earlier one on a tie, as
// numpy's argmin picks the first minimum).
std::size_t nearest_index(const std::vector<Timestamp>& times, int64_t query_ns, int64_t offset_ns) {
  const auto it = std::lower_bound(times.begin(), times.end(), query_ns, [offset_ns](Timestamp t, int64_t q) {
    return t.nanoseconds() + offset_ns < q;
  });
  if (it == times.begin()) return 0;
  if (it == times.end()) return times.size() - 1;
  const auto after = static_cast<std::size_t>(it - times.begin());
  const int64_t distance_after = it->nanoseconds() + offset_ns - query_ns;
  const int64_t distance_before = query_ns - (times[after - 1].nanoseconds() + offset_ns);
  return distance_before <= distance_after ? after - 1 : after;
}

}  // namespace

Result<AssociatedTrajectories> associate(const io::Trajectory& reference, const io::Trajectory& estimate,
                                         const AssociationConfig& config) {
  if (reference.empty() || estimate.empty()) return Error("cannot associate an empty trajectory");
  if (!(config.max_time_difference_s >= 0.0) || !std::isfinite(config.estimate_time_offset_s)) {
    return Error("association: max time difference must be >= 0 and the offset finite");
  }
  const auto offset_ns = static_cast<int64_t>(std::llround(config.estimate_time_offset_s * 1e9));
  const auto max_difference_ns = static_cast<int64_t>(std::llround(config.max_time_difference_s * 1e9));
  // evo walks the trajectory with fewer poses and searches the other one.
  const bool estimate_longer = estimate.size() > reference.size();
  const io::Trajectory& shorter = estimate_longer ? reference : estimate;
  const io::Trajectory& longer = estimate_longer ? estimate : reference;
  // The offset applies to estimate times: shift the longer list by +offset when it is the
  // estimate, otherwise shift the queries (estimate times) by +offset.
  const int64_t longer_offset = estimate_longer ? offset_ns : -offset_ns;

  std::vector<std::size_t> shorter_indices;
  std::vector<std::size_t> longer_indices;
  for (std::size_t i = 0; i < shorter.size(); ++i) {
    const int64_t query = shorter.timestamps[i].nanoseconds();
    const std::size_t j = nearest_index(longer.timestamps, query, longer_offset);
    if (std::llabs(longer.timestamps[j].nanoseconds() + longer_offset - query) <= max_difference_ns) {
      shorter_indices.push_back(i);
      longer_indices.push_back(j);
    }
  }
  if (shorter_indices.empty()) {
    return Error(fmt::format(
        "no matching timestamps between reference ({} .. {} s) and estimate ({} .. {} s) with max difference {} s "
        "and offset {} s",
        io::format_seconds(reference.timestamps.front()), io::format_seconds(reference.timestamps.back()),
        io::format_seconds(estimate.timestamps.front()), io::format_seconds(estimate.timestamps.back()),
        config.max_time_difference_s, config.estimate_time_offset_s));
  }
  AssociatedTrajectories out;
  out.reference_indices = estimate_longer ? shorter_indices : longer_indices;
  out.estimate_indices = estimate_longer ? longer_indices : shorter_indices;
  out.reference = reference.subset(out.reference_indices);
  out.estimate = estimate.subset(out.estimate_indices);
  return out;
}

std::optional<TimeOffsetGuess> guess_relative_time_offset(const io::Trajectory& reference, const io::Trajectory& estimate) {
  if (reference.empty() || estimate.empty()) return std::nullopt;
  const double reference_start = reference.timestamps.front().seconds(), estimate_start = estimate.timestamps.front().seconds();
  const bool reference_relative = reference_start < kRelativeTimesBelow_s, estimate_relative = estimate_start < kRelativeTimesBelow_s;
  if (reference_relative == estimate_relative) return std::nullopt;
  const bool overlap = estimate.timestamps.front() <= reference.timestamps.back() && reference.timestamps.front() <= estimate.timestamps.back();
  if (overlap) return std::nullopt;
  const double absolute_start = reference_relative ? estimate_start : reference_start;
  const double sign = reference_relative ? -1.0 : 1.0;  // the estimate's times move toward the reference's
  if (absolute_start >= kDefaultRelativeTimeOrigin_s && absolute_start < kDefaultRelativeTimeOrigin_s + kRelativeTimesBelow_s) {
    return TimeOffsetGuess{sign * kDefaultRelativeTimeOrigin_s,
                           fmt::format("the {} is in relative times and the {} at the importers' origin {:.0f} s: paired with "
                                       "estimate times {:+.0f} s",
                                       reference_relative ? "reference" : "estimate", reference_relative ? "estimate" : "reference",
                                       kDefaultRelativeTimeOrigin_s, sign * kDefaultRelativeTimeOrigin_s)};
  }
  const double offset = reference_start - estimate_start;
  return TimeOffsetGuess{offset, fmt::format("the {} is in relative times and the {} in absolute ones: paired first time with first "
                                             "time (estimate times {:+.9g} s)",
                                             reference_relative ? "reference" : "estimate", reference_relative ? "estimate" : "reference",
                                             offset)};
}

}  // namespace hanzo::fusion::eval
