#include "hanzo/fusion/core/finite.hpp"

#include <cstdint>
#include <cstring>

namespace hanzo::fusion {
namespace {

// A value is NaN or infinite exactly when all its exponent bits are set (IEEE 754); testing
// the bits instead of calling std::isfinite keeps the loop an integer OR-reduction, which GCC
// vectorizes at -O2/-O3.
template <typename Float, typename Bits, Bits kExponent>
bool all_finite_bits(const Float* values, std::size_t count) {
  static_assert(sizeof(Float) == sizeof(Bits));
  Bits any_non_finite = 0;
  for (std::size_t i = 0; i < count; ++i) {
    Bits bits;
    std::memcpy(&bits, values + i, sizeof(bits));
    any_non_finite |= static_cast<Bits>((bits & kExponent) == kExponent);
  }
  return any_non_finite == 0;
}

}  // namespace

bool all_finite(const float* values, std::size_t count) {
  return all_finite_bits<float, uint32_t, 0x7F800000U>(values, count);
}

bool all_finite(const double* values, std::size_t count) {
  return all_finite_bits<double, uint64_t, 0x7FF0000000000000ULL>(values, count);
}

bool all_within(const float* values, std::size_t count, float low, float high) {
  uint32_t any_outside = 0;
  for (std::size_t i = 0; i < count; ++i) any_outside |= static_cast<uint32_t>(!(values[i] >= low) | !(values[i] <= high));
  return any_outside == 0;
}

}  // namespace hanzo::fusion
