#pragma once
// Observations of segmentation classes in one voxel or cell: (class, count) pairs, few each.

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct ClassVotes {
  std::vector<std::pair<uint16_t, uint32_t>> counts;

  void add(uint16_t label, uint32_t count = 1) {
    const auto found = std::find_if(counts.begin(), counts.end(), [label](const auto& entry) { return entry.first == label; });
    if (found == counts.end()) {
      counts.emplace_back(label, count);
    } else {
      found->second += count;
    }
  }
  /// The most observed class and its count (ties: the lower index); msgs::kNoClass when none.
  std::pair<uint16_t, uint32_t> most() const {
    std::pair<uint16_t, uint32_t> best{msgs::kNoClass, 0};
    for (const auto& [label, count] : counts) {
      if (count > best.second || (count == best.second && label < best.first)) best = {label, count};
    }
    return best;
  }
};

}  // namespace hanzo::fusion::maps
