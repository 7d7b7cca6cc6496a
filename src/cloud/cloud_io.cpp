#include "hanzo/fusion/cloud/cloud_io.hpp"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <filesystem>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"
#include "raw_cloud.hpp"

namespace hanzo::fusion::cloud {
namespace {

enum class Format { kPcd, kPly, kKittiBin };

Result<Format> format_of(const std::string& path) {
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(), [](unsigned char c) { return std::tolower(c); });
  if (extension == ".pcd") return Format::kPcd;
  if (extension == ".ply") return Format::kPly;
  if (extension == ".bin") return Format::kKittiBin;
  return Error(fmt::format("{}: unknown point-cloud format '{}' (expected .pcd, .ply or .bin)", path, extension));
}

Result<PointCloud> parse_kitti_bin(const std::string& bytes) {
  constexpr size_t kPointBytes = 4 * sizeof(float);
  if (bytes.size() % kPointBytes != 0) {
    return Error(fmt::format("{} bytes is not a whole number of 16-byte KITTI points", bytes.size()));
  }
  PointCloud cloud;
  const size_t count = bytes.size() / kPointBytes;
  cloud.positions.resize(count);
  cloud.intensities.resize(count);
  for (size_t i = 0; i < count; ++i) {
    float values[4];
    std::memcpy(values, bytes.data() + i * kPointBytes, kPointBytes);
    cloud.positions[i] = Eigen::Vector3f(values[0], values[1], values[2]);
    cloud.intensities[i] = values[3];
  }
  HANZO_RETURN_IF_ERROR(cloud.validate());
  return cloud;
}

std::string kitti_bytes(const PointCloud& cloud) {
  std::string bytes(cloud.size() * 4 * sizeof(float), '\0');
  for (size_t i = 0; i < cloud.size(); ++i) {
    const float values[4] = {cloud.positions[i].x(), cloud.positions[i].y(), cloud.positions[i].z(),
                             cloud.has_intensities() ? cloud.intensities[i] : 0.0f};
    std::memcpy(bytes.data() + i * sizeof(values), values, sizeof(values));
  }
  return bytes;
}

Result<PointCloud> parse(Format format, const std::string& bytes, bool drop_non_finite) {
  if (format == Format::kKittiBin) return parse_kitti_bin(bytes);
  RawCloud raw;
  HANZO_ASSIGN_OR_RETURN(raw, format == Format::kPcd ? parse_pcd(bytes) : parse_ply(bytes));
  return to_point_cloud(raw, drop_non_finite);
}

}  // namespace

Result<PointCloud> read_cloud(const std::string& path, bool drop_non_finite) {
  Format format = Format::kPcd;
  HANZO_ASSIGN_OR_RETURN(format, format_of(path));
  std::error_code error;
  if (!std::filesystem::is_regular_file(path, error)) return Error(fmt::format("{}: no such file", path));
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, read_file(path));
  return with_context(parse(format, bytes, drop_non_finite), path);
}

Result<std::string> encode_cloud(const PointCloud& cloud, std::string_view format) {
  if (auto status = cloud.validate(); !status) return status.error();
  if (format == "pcd") return format_pcd(to_raw_cloud(cloud));
  if (format == "ply") return format_ply(to_raw_cloud(cloud));
  if (format == "bin") return kitti_bytes(cloud);
  return Error(fmt::format("unknown point cloud format '{}' (pcd, ply or bin)", format));
}

Status write_cloud(const std::string& path, const PointCloud& cloud) {
  Format format = Format::kPcd;
  HANZO_ASSIGN_OR_RETURN(format, format_of(path));
  static constexpr const char* kNames[] = {"pcd", "ply", "bin"};
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, with_context(encode_cloud(cloud, kNames[static_cast<int>(format)]), path));
  return yaml::write_file_atomically(path, bytes);
}

}  // namespace hanzo::fusion::cloud
