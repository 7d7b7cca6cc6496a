#pragma once
// Whole-array finiteness checks for validating large inputs (10^5-point clouds): one
// branch-free pass the compiler vectorizes, so a caller searches for the offending element
// (to name it in its error) only when there is one.

#include <cstddef>

namespace hanzo::fusion {

/// True when none of values[0, count) is NaN or +-infinity (count 0: true).
bool all_finite(const float* values, std::size_t count);
bool all_finite(const double* values, std::size_t count);

/// True when every values[i] lies in [low, high] (NaN fails; count 0: true).
bool all_within(const float* values, std::size_t count, float low, float high);

}  // namespace hanzo::fusion
