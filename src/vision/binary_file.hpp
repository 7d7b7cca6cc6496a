#pragma once
// Little-endian values appended to and read from the byte strings of the vision module's model
// files (vocabulary.cpp, vlad.cpp), and their trailing crc32.

#include <cstdint>
#include <cstring>
#include <string>

#include <zlib.h>

namespace hanzo::fusion::vision::binary_file {

template <typename T>
void put(std::string& out, T value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

/// The value at `offset` (the caller checked the size), and the offset moved past it.
template <typename T>
T take(const std::string& bytes, std::size_t& offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof(T));
  offset += sizeof(T);
  return value;
}

/// crc32 of the first `size` bytes.
inline uint32_t crc32_of(const std::string& bytes, std::size_t size) {
  return static_cast<uint32_t>(::crc32(0L, reinterpret_cast<const Bytef*>(bytes.data()), static_cast<uInt>(size)));
}

}  // namespace hanzo::fusion::vision::binary_file
