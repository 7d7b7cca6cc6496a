#include "hanzo/fusion/io/image_file_check.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <cstdint>
#include <filesystem>
#include <string_view>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"

namespace hanzo::fusion::io {
namespace {

uint8_t byte_at(const std::string& bytes, std::size_t i) { return static_cast<uint8_t>(bytes[i]); }

// JPEG markers without a length field: TEM, RST0-7, SOI, EOI.
bool standalone_marker(uint8_t marker) { return marker == 0x01 || (marker >= 0xD0 && marker <= 0xD9); }

Status check_jpeg(const std::string& bytes, const std::string& name) {
  const auto truncated = [&](std::size_t at, const char* where) {
    return Error(fmt::format("{}: truncated JPEG: the data ends at byte {} {} before the end-of-image marker", name, at, where));
  };
  std::size_t i = 2;  // after SOI
  while (true) {
    // Fill bytes (0xFF repeated) may precede a marker.
    if (i >= bytes.size()) return truncated(bytes.size(), "between segments");
    if (byte_at(bytes, i) != 0xFF) return Error(fmt::format("{}: corrupt JPEG: expected a marker at byte {}", name, i));
    while (i < bytes.size() && byte_at(bytes, i) == 0xFF) ++i;
    if (i >= bytes.size()) return truncated(bytes.size(), "in a marker");
    const uint8_t marker = byte_at(bytes, i++);
    if (marker == 0xD9) return ok_status();  // EOI
    if (standalone_marker(marker)) continue;
    if (i + 2 > bytes.size()) return truncated(bytes.size(), "in a segment length");
    const std::size_t length = (static_cast<std::size_t>(byte_at(bytes, i)) << 8) | byte_at(bytes, i + 1);
    if (length < 2) return Error(fmt::format("{}: corrupt JPEG: segment length {} at byte {}", name, length, i));
    if (i + length > bytes.size()) return truncated(bytes.size(), "inside a segment");
    i += length;
    if (marker != 0xDA) continue;  // SOS: entropy-coded data follows up to the next marker
    while (true) {
      if (i + 1 >= bytes.size()) return truncated(bytes.size(), "in the compressed image data");
      if (byte_at(bytes, i) == 0xFF) {
        const uint8_t next = byte_at(bytes, i + 1);
        if (next != 0x00 && !(next >= 0xD0 && next <= 0xD7) && next != 0xFF) break;  // a real marker
      }
      ++i;
    }
  }
}

Status check_png(const std::string& bytes, const std::string& name) {
  std::size_t i = 8;  // after the signature
  while (true) {
    if (i + 8 > bytes.size()) return Error(fmt::format("{}: truncated PNG: the data ends at byte {} before the IEND chunk", name, bytes.size()));
    const std::size_t length = (static_cast<std::size_t>(byte_at(bytes, i)) << 24) | (static_cast<std::size_t>(byte_at(bytes, i + 1)) << 16) |
                               (static_cast<std::size_t>(byte_at(bytes, i + 2)) << 8) | byte_at(bytes, i + 3);
    const std::string type = bytes.substr(i + 4, 4);
    if (i + 12 + length > bytes.size()) {
      return Error(fmt::format("{}: truncated PNG: the data ends at byte {} inside the {} chunk", name, bytes.size(), type));
    }
    if (type == "IEND") return ok_status();
    i += 12 + length;
  }
}

}  // namespace

bool has_image_extension(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  static constexpr std::array<std::string_view, 10> kExtensions = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".pnm", ".webp"};
  return std::find(kExtensions.begin(), kExtensions.end(), extension) != kExtensions.end();
}

Status check_image_complete(const std::string& bytes, const std::string& name) {
  if (bytes.size() >= 3 && byte_at(bytes, 0) == 0xFF && byte_at(bytes, 1) == 0xD8 && byte_at(bytes, 2) == 0xFF) return check_jpeg(bytes, name);
  if (bytes.size() >= 8 && bytes.compare(0, 8, "\x89PNG\r\n\x1a\n") == 0) return check_png(bytes, name);
  return ok_status();
}

Status check_image_file_complete(const std::string& path) {
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, read_file(path));
  return check_image_complete(bytes, path);
}

}  // namespace hanzo::fusion::io
