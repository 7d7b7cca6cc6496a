#pragma once
// Little-endian fields of LiDAR packets (Velodyne, Hesai); the caller checked the size.

#include <cstddef>
#include <cstdint>
#include <string_view>

namespace hanzo::fusion::drivers {

inline uint16_t little16(std::string_view data, std::size_t at) {
  return static_cast<uint16_t>(static_cast<uint8_t>(data[at]) | (static_cast<uint8_t>(data[at + 1]) << 8));
}

inline uint32_t little32(std::string_view data, std::size_t at) {
  return static_cast<uint32_t>(little16(data, at)) | (static_cast<uint32_t>(little16(data, at + 2)) << 16);
}

}  // namespace hanzo::fusion::drivers
