#include "hanzo/fusion/maps/map_store.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstring>
#include <filesystem>
#include <random>

#include <fmt/format.h>
#include <unistd.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::maps {
namespace {

namespace fs = std::filesystem;

constexpr std::string_view kExtension = ".fmap";
constexpr std::size_t kVersionDigits = 20;

/// The version a file name holds ("00000000000000000003.fmap" -> 3), if it is a version file.
std::optional<uint64_t> version_of(const std::string& file_name) {
  if (file_name.size() != kVersionDigits + kExtension.size() || !file_name.ends_with(kExtension)) return std::nullopt;
  uint64_t version = 0;
  const char* end = file_name.data() + kVersionDigits;
  const auto [rest, error] = std::from_chars(file_name.data(), end, version);
  if (error != std::errc{} || rest != end || version == 0) return std::nullopt;
  return version;
}


}  // namespace

std::string generate_map_id() {
  std::random_device device;
  std::mt19937_64 generator((static_cast<uint64_t>(device()) << 32) ^ device() ^
                            static_cast<uint64_t>(Timestamp::wall_clock_now().nanoseconds()));
  uint64_t high = generator();
  uint64_t low = generator();
  high = (high & ~uint64_t{0xf000}) | 0x4000;                  // version 4
  low = (low & ~(uint64_t{0xc} << 60)) | (uint64_t{0x8} << 60);  // variant 10xx
  return fmt::format("{:08x}-{:04x}-{:04x}-{:04x}-{:012x}", high >> 32, (high >> 16) & 0xffff, high & 0xffff, low >> 48,
                     low & 0xffffffffffffULL);
}

Status validate_map_id(const std::string& map_id) {
  if (map_id.empty() || map_id.size() > 128) {
    return Error{fmt::format("map_id: must be 1 to 128 characters, got {}", map_id.size()), "map_id"};
  }
  if (map_id.front() == '.') return Error{fmt::format("map_id '{}': must not start with '.'", map_id), "map_id"};
  for (char c : map_id) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-')) {
      return Error{fmt::format("map_id '{}': only letters, digits, '.', '_' and '-' are allowed", map_id), "map_id"};
    }
  }
  return ok_status();
}

Result<MapStore> MapStore::open(const std::string& root, const FusionMapFileConfig& file_config) {
  std::error_code error;
  fs::create_directories(root, error);
  if (error || !fs::is_directory(root)) {
    return Error{fmt::format("{}: cannot create the map store folder ({})", root, error ? error.message() : "not a folder")};
  }
  return MapStore(root, file_config);
}

std::string MapStore::version_path(const std::string& map_id, uint64_t version) const {
  return fmt::format("{}/{}/{:0{}}{}", root_, map_id, version, kVersionDigits, kExtension);
}

Result<MapVersionInfo> MapStore::save(msgs::FusionMap map) {
  if (map.map_id.empty()) map.map_id = generate_map_id();
  HANZO_RETURN_IF_ERROR(validate_map_id(map.map_id));
  const std::string folder = fmt::format("{}/{}", root_, map.map_id);
  std::error_code fs_error;
  fs::create_directories(folder, fs_error);
  if (fs_error) return Error{fmt::format("{}: cannot create folder ({})", folder, fs_error.message())};

  std::vector<MapVersionInfo> existing;
  HANZO_ASSIGN_OR_RETURN(existing, versions(map.map_id));
  uint64_t version = existing.empty() ? 1 : existing.back().version + 1;
  // The parent is the stored version this map was loaded as; a map that never came from the
  // store (or from another store) starts a new lineage.
  const bool derived = std::any_of(existing.begin(), existing.end(), [&](const MapVersionInfo& info) { return info.version == map.version; });
  map.parent_version = derived ? map.version : 0;
  if (map.created.nanoseconds() == 0) map.created = Timestamp::wall_clock_now();

  const std::string temporary = fmt::format("{}/.{}-{}.tmp", folder, ::getpid(), generate_map_id());
  // Another writer may take a version between our listing and our link: try the next ones.
  for (int attempt = 0; attempt < 64; ++attempt, ++version) {
    map.version = version;
    std::string bytes;
    HANZO_ASSIGN_OR_RETURN(bytes, serialize_fusion_map(map, file_config_));
    HANZO_RETURN_IF_ERROR(write_file_durably(temporary, bytes));
    const std::string path = version_path(map.map_id, version);
    const int linked = ::link(temporary.c_str(), path.c_str());
    const int link_errno = errno;
    ::unlink(temporary.c_str());
    if (linked == 0) {
      HANZO_RETURN_IF_ERROR(sync_directory(folder));
      logger()->info("map store: saved {} version {} ({} bytes)", map.map_id, version, bytes.size());
      return MapVersionInfo{map.map_id, version, map.parent_version, map.created, bytes.size(), path};
    }
    if (link_errno != EEXIST) return Error{fmt::format("{}: cannot store ({})", path, std::strerror(link_errno))};
  }
  return Error{fmt::format("map {}: could not find a free version number (too many concurrent writers)", map.map_id)};
}

Result<std::vector<std::string>> MapStore::map_ids() const {
  std::vector<std::string> ids;
  std::error_code error;
  for (fs::directory_iterator it(root_, error), end; !error && it != end; it.increment(error)) {
    const std::string name = it->path().filename().string();
    if (it->is_directory() && validate_map_id(name)) ids.push_back(name);
  }
  if (error) return Error{fmt::format("{}: cannot list ({})", root_, error.message())};
  std::sort(ids.begin(), ids.end());
  return ids;
}

Result<std::vector<MapVersionInfo>> MapStore::versions(const std::string& map_id) const {
  HANZO_RETURN_IF_ERROR(validate_map_id(map_id));
  const std::string folder = fmt::format("{}/{}", root_, map_id);
  std::vector<uint64_t> numbers;
  std::error_code error;
  if (!fs::is_directory(folder)) return std::vector<MapVersionInfo>{};
  for (fs::directory_iterator it(folder, error), end; !error && it != end; it.increment(error)) {
    if (const auto version = version_of(it->path().filename().string())) numbers.push_back(*version);
  }
  if (error) return Error{fmt::format("{}: cannot list ({})", folder, error.message())};
  std::sort(numbers.begin(), numbers.end());

  std::vector<MapVersionInfo> infos;
  for (uint64_t version : numbers) {
    const std::string path = version_path(map_id, version);
    msgs::FusionMap metadata;
    HANZO_ASSIGN_OR_RETURN(metadata, read_fusion_map_metadata(path));
    if (metadata.version != version || metadata.map_id != map_id) {
      return Error{fmt::format("{}: holds map {} version {}, not what its name says", path, metadata.map_id, metadata.version)};
    }
    infos.push_back({map_id, version, metadata.parent_version, metadata.created, fs::file_size(path, error), path});
  }
  return infos;
}

Result<msgs::FusionMap> MapStore::load(const std::string& map_id, std::optional<uint64_t> version) const {
  std::vector<MapVersionInfo> all;
  HANZO_ASSIGN_OR_RETURN(all, versions(map_id));
  if (all.empty()) return Error{fmt::format("map {}: not in the store {}", map_id, root_), "map_id"};
  if (!version) return read_fusion_map(all.back().path);
  const auto found = std::find_if(all.begin(), all.end(), [&](const MapVersionInfo& info) { return info.version == *version; });
  if (found == all.end()) {
    return Error{fmt::format("map {}: no version {} (stored: {} versions, {} to {})", map_id, *version, all.size(), all.front().version,
                             all.back().version),
                 "version"};
  }
  return read_fusion_map(found->path);
}

Result<msgs::FusionMap> MapStore::load_at(const std::string& map_id, Timestamp time) const {
  std::vector<MapVersionInfo> all;
  HANZO_ASSIGN_OR_RETURN(all, versions(map_id));
  const MapVersionInfo* chosen = nullptr;
  for (const MapVersionInfo& info : all) {
    if (info.created <= time && (chosen == nullptr || info.version > chosen->version)) chosen = &info;
  }
  if (chosen == nullptr) {
    return Error{fmt::format("map {}: no version was created at or before {} s", map_id, time.seconds()), "time"};
  }
  return read_fusion_map(chosen->path);
}


Status MapStore::remove_version(const std::string& map_id, uint64_t version) {
  std::vector<MapVersionInfo> all;
  HANZO_ASSIGN_OR_RETURN(all, versions(map_id));
  const auto found = std::find_if(all.begin(), all.end(), [&](const MapVersionInfo& info) { return info.version == version; });
  if (found == all.end()) return Error{fmt::format("map {}: no version {}", map_id, version), "version"};
  if (version == all.back().version) {
    return Error{fmt::format("map {}: version {} is the newest; delete the map, or save a newer version first", map_id, version), "version"};
  }
  if (::unlink(found->path.c_str()) != 0) return Error{fmt::format("{}: cannot delete ({})", found->path, std::strerror(errno))};
  HANZO_RETURN_IF_ERROR(sync_directory(fmt::format("{}/{}", root_, map_id)));
  logger()->info("map store: deleted {} version {}", map_id, version);
  return ok_status();
}

Status MapStore::remove_map(const std::string& map_id) {
  HANZO_RETURN_IF_ERROR(validate_map_id(map_id));
  const std::string folder = fmt::format("{}/{}", root_, map_id);
  if (!fs::is_directory(folder)) return Error{fmt::format("map {}: not in the store {}", map_id, root_), "map_id"};
  // Oldest first: a failure part way leaves the newest versions, which load() serves.
  std::vector<MapVersionInfo> all;
  HANZO_ASSIGN_OR_RETURN(all, versions(map_id));
  for (const MapVersionInfo& info : all) {
    if (::unlink(info.path.c_str()) != 0) return Error{fmt::format("{}: cannot delete ({})", info.path, std::strerror(errno))};
  }
  std::error_code error;
  fs::remove_all(folder, error);  // what is left: temporary files of interrupted saves
  if (error) return Error{fmt::format("{}: cannot delete ({})", folder, error.message())};
  HANZO_RETURN_IF_ERROR(sync_directory(root_));
  logger()->info("map store: deleted {} ({} versions)", map_id, all.size());
  return ok_status();
}

}  // namespace hanzo::fusion::maps
