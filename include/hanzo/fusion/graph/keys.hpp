#pragma once
// Keys of factor-graph variables, as GTSAM users know them: a symbol character and an index
// packed into 64 bits (8 bits character, 56 bits index). X(i) poses, V(i) velocities, B(i) IMU
// biases, L(j) landmarks, E(i) GNSS position errors.

#include <cstdint>
#include <string>

namespace hanzo::fusion::graph {

using Key = uint64_t;

constexpr Key symbol(char character, uint64_t index) {
  return (static_cast<uint64_t>(static_cast<unsigned char>(character)) << 56) | (index & ((uint64_t{1} << 56) - 1));
}
constexpr char symbol_character(Key key) { return static_cast<char>(key >> 56); }
constexpr uint64_t symbol_index(Key key) { return key & ((uint64_t{1} << 56) - 1); }

constexpr Key X(uint64_t i) { return symbol('x', i); }
constexpr Key V(uint64_t i) { return symbol('v', i); }
constexpr Key B(uint64_t i) { return symbol('b', i); }
constexpr Key L(uint64_t j) { return symbol('l', j); }
constexpr Key E(uint64_t i) { return symbol('e', i); }

/// "x12"; keys without a printable symbol character print as the plain number.
std::string key_to_string(Key key);

}  // namespace hanzo::fusion::graph
