#pragma once
// Integer division rounding toward minus infinity: the block (or coarse cell) holding a cell
// index, for negative indices too.

namespace hanzo::fusion::maps {

inline int floor_divide(int value, int divisor) {
  const int quotient = value / divisor;
  return (value % divisor != 0 && (value < 0) != (divisor < 0)) ? quotient - 1 : quotient;
}

}  // namespace hanzo::fusion::maps
