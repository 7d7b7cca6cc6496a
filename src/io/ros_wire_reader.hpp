#pragma once
// A sequential reader of the two ROS wire formats behind one interface, so that each message
// layout is written once (ros_conversion.cpp):
//
//   ROS 1: little-endian, packed (no alignment); strings and variable arrays prefixed by a
//          uint32 count; time = uint32 sec + uint32 nsec; std_msgs/Header = seq, stamp, frame_id.
//   CDR (ROS 2; XCDR1, and XCDR2 plain for the fixed-layout messages read here): a 4-byte
//          encapsulation header (0x00 0x00 big-endian, 0x00 0x01 little-endian; 0x00 0x06 /
//          0x00 0x07 PLAIN_CDR2 BE / LE), then every primitive aligned to its size (at most 4 in
//          CDR2) counted from the end of that header; strings = uint32 length including the
//          terminating NUL, then the bytes; time = int32 sec + uint32 nanosec;
//          std_msgs/Header = stamp, frame_id.
//
// Reading past the end (or a CDR buffer without a known encapsulation header) sets ok() to false
// and returns zeros; callers check ok() once after reading a message.

#include <algorithm>
#include <array>
#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/io/ros_conversion.hpp"

namespace hanzo::fusion::io::ros {

class WireReader {
 public:
  WireReader(std::string_view data, Serialization serialization) : data_(data), cdr_(serialization == Serialization::kCdr) {
    if (!cdr_) return;
    if (data.size() < 4 || data[0] != 0) {
      ok_ = false;
      return;
    }
    switch (data[1]) {
      case 0x00: big_endian_ = true; break;
      case 0x01: break;
      case 0x06: big_endian_ = true; max_alignment_ = 4; break;
      case 0x07: max_alignment_ = 4; break;
      default: ok_ = false; return;  // parameter lists (PL_CDR) and delimited CDR2 are not fixed layouts
    }
    data_ = data.substr(4);
  }
  bool ok() const { return ok_; }
  bool can_take(uint64_t n) const { return ok_ && n <= data_.size() - position_; }

  template <typename T>
  T integer() {
    if (cdr_) {
      const std::size_t alignment = std::min(sizeof(T), max_alignment_);
      take((alignment - position_ % alignment) % alignment);
    }
    if (!take(sizeof(T))) return 0;
    uint64_t value = 0;
    for (std::size_t i = 0; i < sizeof(T); ++i) {
      const std::size_t byte = big_endian_ ? sizeof(T) - 1 - i : i;
      value |= static_cast<uint64_t>(static_cast<unsigned char>(data_[position_ - sizeof(T) + byte])) << (8 * i);
    }
    return static_cast<T>(value);
  }
  uint8_t u8() { return integer<uint8_t>(); }
  int8_t i8() { return static_cast<int8_t>(u8()); }
  uint16_t u16() { return integer<uint16_t>(); }
  uint32_t u32() { return integer<uint32_t>(); }
  int32_t i32() { return static_cast<int32_t>(u32()); }
  float f32() {
    const uint32_t bits = integer<uint32_t>();
    float value;
    std::memcpy(&value, &bits, sizeof value);
    return value;
  }
  double f64() {
    const uint64_t bits = integer<uint64_t>();
    double value;
    std::memcpy(&value, &bits, sizeof value);
    return value;
  }
  /// uint8[] (a uint32 count, then the bytes).
  std::string_view bytes() {
    const uint32_t n = u32();
    if (!take(n)) return {};
    return data_.substr(position_ - n, n);
  }
  std::string string() {
    std::string_view text = bytes();
    if (cdr_ && !text.empty() && text.back() == '\0') text.remove_suffix(1);
    return std::string(text);
  }
  Timestamp time() {
    const uint32_t sec = u32();  // int32 in ROS 2: stamps before 1970 are not sensor data
    const uint32_t nanoseconds = u32();
    return Timestamp::from_nanoseconds(static_cast<int64_t>(sec) * 1'000'000'000 + nanoseconds);
  }
  /// std_msgs/Header: stamp and frame_id.
  std::pair<Timestamp, std::string> header() {
    if (!cdr_) u32();  // seq
    const Timestamp stamp = time();
    return {stamp, string()};
  }
  template <std::size_t N>
  std::array<double, N> f64_array() {
    std::array<double, N> values{};
    for (double& v : values) v = f64();
    return values;
  }
  /// float64[] (a uint32 count, then the values).
  std::vector<double> f64_sequence() {
    const uint32_t count = u32();
    if (!can_take(static_cast<uint64_t>(count) * 8)) {
      ok_ = false;
      return {};
    }
    std::vector<double> values(count);
    for (double& v : values) v = f64();
    return values;
  }
  Eigen::Vector3d vector3() {
    const double x = f64(), y = f64(), z = f64();
    return {x, y, z};
  }
  /// geometry_msgs/Quaternion (x, y, z, w on the wire) as (w, x, y, z).
  Eigen::Vector4d quaternion_wxyz() {
    const double x = f64(), y = f64(), z = f64(), w = f64();
    return {w, x, y, z};
  }

 private:
  bool take(uint64_t n) {
    if (!can_take(n)) {
      ok_ = false;
      return false;
    }
    position_ += n;
    return true;
  }
  std::string_view data_;
  std::size_t position_ = 0;
  bool cdr_;
  std::size_t max_alignment_ = 8;
  bool big_endian_ = false;
  bool ok_ = true;
};

}  // namespace hanzo::fusion::io::ros
