#include "hanzo/fusion/maps/map_store.hpp"

#include <algorithm>
#include <charconv>
#include <map>
#include <mutex>
#include <random>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::maps {
namespace {

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

struct MapStore::MetadataCache {
  std::mutex mutex;
  std::map<std::string, MapVersionInfo> versions;  // by object key, size and time: versions are immutable
};

namespace {
std::string cache_key(const object_store::ObjectInfo& object) {
  return fmt::format("{}|{}|{}", object.key, object.size, object.modified.nanoseconds());
}
}  // namespace

Result<MapStore> MapStore::open(const std::string& url, MapStoreConfig config) {
  std::unique_ptr<object_store::ObjectStore> objects;
  HANZO_ASSIGN_OR_RETURN(objects, object_store::open_object_store(url));
  return MapStore(std::move(objects), "", std::move(config));
}

MapStore::MapStore(std::shared_ptr<object_store::ObjectStore> objects, std::string key_prefix, MapStoreConfig config)
    : objects_(std::move(objects)), prefix_(std::move(key_prefix)), config_(std::move(config)), cache_(std::make_shared<MetadataCache>()) {
  if (!prefix_.empty() && !prefix_.ends_with('/')) prefix_ += '/';
  if (config_.encryption_key) keys_.push_back(*config_.encryption_key);
  keys_.insert(keys_.end(), config_.decryption_keys.begin(), config_.decryption_keys.end());
}

std::string MapStore::location() const { return prefix_.empty() ? objects_->location() : objects_->location_of(prefix_); }

std::string MapStore::version_key(const std::string& map_id, uint64_t version) const {
  return fmt::format("{}{}/{:0{}}{}", prefix_, map_id, version, kVersionDigits, kExtension);
}

Result<MapVersionInfo> MapStore::save(msgs::FusionMap map) {
  if (map.map_id.empty()) map.map_id = generate_map_id();
  HANZO_RETURN_IF_ERROR(validate_map_id(map.map_id));
  std::vector<MapVersionInfo> existing;
  HANZO_ASSIGN_OR_RETURN(existing, versions(map.map_id));
  uint64_t version = existing.empty() ? 1 : existing.back().version + 1;
  // The parent is the stored version this map was loaded as; a map that never came from the
  // store (or from another store) starts a new lineage.
  const bool derived = std::any_of(existing.begin(), existing.end(), [&](const MapVersionInfo& info) { return info.version == map.version; });
  map.parent_version = derived ? map.version : 0;
  if (map.created.nanoseconds() == 0) map.created = Timestamp::wall_clock_now();

  // Another writer may take a version between our listing and our write: try the next ones.
  for (int attempt = 0; attempt < 64; ++attempt, ++version) {
    map.version = version;
    std::string bytes;
    HANZO_ASSIGN_OR_RETURN(bytes, serialize_fusion_map(map, config_.file));
    if (config_.encryption_key) bytes = crypto::encrypt(bytes, *config_.encryption_key);
    const std::string key = version_key(map.map_id, version);
    bool stored = false;
    HANZO_ASSIGN_OR_RETURN(stored, objects_->put_if_absent(key, bytes));
    if (stored) {
      logger()->info("map store: saved {} version {} ({} bytes{})", map.map_id, version, bytes.size(), config_.encryption_key ? ", encrypted" : "");
      return MapVersionInfo{map.map_id,
                            version,
                            map.parent_version,
                            map.created,
                            bytes.size(),
                            objects_->location_of(key),
                            config_.encryption_key ? config_.encryption_key->id() : std::string{},
                            {}};
    }
  }
  return Error{fmt::format("map {}: could not find a free version number (too many concurrent writers)", map.map_id)};
}

Result<std::vector<std::string>> MapStore::map_ids() const {
  std::vector<object_store::ObjectInfo> objects;
  HANZO_ASSIGN_OR_RETURN(objects, objects_->list(prefix_));
  std::vector<std::string> ids;
  for (const object_store::ObjectInfo& object : objects) {
    const std::string relative = object.key.substr(prefix_.size());
    const auto slash = relative.find('/');
    if (slash == std::string::npos || !version_of(relative.substr(slash + 1))) continue;
    std::string id = relative.substr(0, slash);
    if (validate_map_id(id) && (ids.empty() || ids.back() != id)) ids.push_back(std::move(id));
  }
  return ids;  // listings are sorted by key, so ids come sorted and grouped
}

Result<MapVersionInfo> MapStore::read_version_info(const object_store::ObjectInfo& object, const std::string& map_id, uint64_t version) const {
  {
    std::lock_guard lock(cache_->mutex);
    if (const auto found = cache_->versions.find(cache_key(object)); found != cache_->versions.end()) return found->second;
  }
  // The metadata is the file's first chunk: read that much (through the decryption when encrypted).
  const std::string where = objects_->location_of(object.key);
  constexpr uint64_t kPeekBytes = 64 << 10;
  std::string head;
  HANZO_ASSIGN_OR_RETURN(head, objects_->get_range(object.key, 0, kPeekBytes));
  MapVersionInfo info{map_id, version, 0, Timestamp{}, object.size, where, {}, {}};
  const bool encrypted = crypto::is_encrypted(head);
  auto plaintext_prefix = [&](uint64_t plaintext_bytes) -> Result<std::string> {
    if (!encrypted) return plaintext_bytes <= head.size() ? head : objects_->get_range(object.key, 0, plaintext_bytes);
    // Whole encryption chunks (1 MiB of plaintext each); when that is the whole file, all of it
    // is checked (a truncated file says so).
    constexpr uint64_t kChunk = uint64_t{1} << 20;
    const uint64_t wanted = crypto::encrypted_prefix_bytes(std::max<uint64_t>(1, (plaintext_bytes + kChunk - 1) / kChunk) * kChunk);
    std::string first;
    HANZO_ASSIGN_OR_RETURN(first, objects_->get_range(object.key, 0, wanted));
    Result<std::string> plaintext = first.size() < wanted ? crypto::decrypt(first, keys_) : crypto::decrypt_prefix(first, keys_);
    if (!plaintext) return Error{fmt::format("{}: {}", where, plaintext.error().message)};
    return plaintext;
  };
  if (encrypted) {
    Result<std::string> key_id = crypto::encrypted_key_id_of(head);
    info.key_id = key_id ? *key_id : std::string{};
  }
  // A version whose first bytes do not decode (damaged, or its key not given) is listed with the
  // reason; failing to fetch them at all (the store unreachable) is an error.
  const auto unreadable = [&](const std::string& reason) {
    info.unreadable = reason;
    logger()->warn("map store: {}", reason);
    return info;
  };
  std::string plaintext;
  Result<std::string> peeked = plaintext_prefix(kPeekBytes);
  if (!peeked) return unreadable(peeked.error().message);
  plaintext = std::move(peeked).value();
  Result<uint64_t> needed = fusion_map_metadata_bytes(plaintext);
  if (!needed) return unreadable(fmt::format("{}: {}", where, needed.error().message));
  if (*needed > plaintext.size()) {
    Result<std::string> longer = plaintext_prefix(*needed);
    if (!longer) return unreadable(longer.error().message);
    plaintext = std::move(longer).value();
  }
  Result<msgs::FusionMap> metadata = parse_fusion_map_metadata(plaintext, where);
  if (!metadata) return unreadable(metadata.error().message);
  if (metadata->version != version || metadata->map_id != map_id) {
    return unreadable(fmt::format("{}: holds map {} version {}, not what its name says", where, metadata->map_id, metadata->version));
  }
  info.parent_version = metadata->parent_version;
  info.created = metadata->created;
  std::lock_guard lock(cache_->mutex);
  cache_->versions[cache_key(object)] = info;
  return info;
}

Result<std::vector<MapVersionInfo>> MapStore::versions(const std::string& map_id) const {
  HANZO_RETURN_IF_ERROR(validate_map_id(map_id));
  const std::string folder = prefix_ + map_id + "/";
  std::vector<object_store::ObjectInfo> objects;
  HANZO_ASSIGN_OR_RETURN(objects, objects_->list(folder));
  std::vector<std::pair<uint64_t, const object_store::ObjectInfo*>> numbered;
  for (const object_store::ObjectInfo& object : objects) {
    const std::string name = object.key.substr(folder.size());
    if (const auto version = version_of(name); version && name.find('/') == std::string::npos) numbered.emplace_back(*version, &object);
  }
  std::sort(numbered.begin(), numbered.end());
  std::vector<MapVersionInfo> infos;
  for (const auto& [version, object] : numbered) {
    MapVersionInfo info;
    HANZO_ASSIGN_OR_RETURN(info, read_version_info(*object, map_id, version));
    infos.push_back(std::move(info));
  }
  return infos;
}

Result<std::string> MapStore::read_plaintext(const MapVersionInfo& info) const {
  if (!info.unreadable.empty()) return Error{info.unreadable};
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, objects_->get(version_key(info.map_id, info.version)));
  if (!crypto::is_encrypted(bytes)) return bytes;
  Result<std::string> plaintext = crypto::decrypt(bytes, keys_);
  if (!plaintext) return Error{fmt::format("{}: {}", info.location, plaintext.error().message)};
  return plaintext;
}

Result<const MapVersionInfo*> MapStore::find_version(const std::vector<MapVersionInfo>& all, const std::string& map_id,
                                                     std::optional<uint64_t> version) const {
  if (all.empty()) return Error{fmt::format("map {}: not in the store {}", map_id, location()), "map_id"};
  if (!version) return &all.back();
  const auto found = std::find_if(all.begin(), all.end(), [&](const MapVersionInfo& info) { return info.version == *version; });
  if (found == all.end()) {
    return Error{fmt::format("map {}: no version {} (stored: {} versions, {} to {})", map_id, *version, all.size(), all.front().version,
                             all.back().version),
                 "version"};
  }
  return &*found;
}

Result<std::pair<uint64_t, std::string>> MapStore::file(const std::string& map_id, std::optional<uint64_t> version) const {
  std::vector<MapVersionInfo> all;
  HANZO_ASSIGN_OR_RETURN(all, versions(map_id));
  const MapVersionInfo* chosen = nullptr;
  HANZO_ASSIGN_OR_RETURN(chosen, find_version(all, map_id, version));
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, read_plaintext(*chosen));
  return std::make_pair(chosen->version, std::move(bytes));
}

Result<msgs::FusionMap> MapStore::load(const std::string& map_id, std::optional<uint64_t> version) const {
  std::pair<uint64_t, std::string> stored;
  HANZO_ASSIGN_OR_RETURN(stored, file(map_id, version));
  return parse_fusion_map(stored.second, objects_->location_of(version_key(map_id, stored.first)));
}

Result<msgs::FusionMap> MapStore::load_at(const std::string& map_id, Timestamp time) const {
  std::vector<MapVersionInfo> all;
  HANZO_ASSIGN_OR_RETURN(all, versions(map_id));
  const MapVersionInfo* chosen = nullptr;
  for (const MapVersionInfo& info : all) {
    if (info.unreadable.empty() && info.created <= time && (chosen == nullptr || info.version > chosen->version)) chosen = &info;
  }
  if (chosen == nullptr) {
    return Error{fmt::format("map {}: no version was created at or before {} s", map_id, time.seconds()), "time"};
  }
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, read_plaintext(*chosen));
  return parse_fusion_map(bytes, chosen->location);
}

Status MapStore::remove_version(const std::string& map_id, uint64_t version) {
  std::vector<MapVersionInfo> all;
  HANZO_ASSIGN_OR_RETURN(all, versions(map_id));
  const auto found = std::find_if(all.begin(), all.end(), [&](const MapVersionInfo& info) { return info.version == version; });
  if (found == all.end()) return Error{fmt::format("map {}: no version {}", map_id, version), "version"};
  if (version == all.back().version) {
    return Error{fmt::format("map {}: version {} is the newest; delete the map, or save a newer version first", map_id, version), "version"};
  }
  HANZO_RETURN_IF_ERROR(objects_->remove(version_key(map_id, version)));
  logger()->info("map store: deleted {} version {}", map_id, version);
  return ok_status();
}

Status MapStore::remove_map(const std::string& map_id) {
  std::vector<MapVersionInfo> all;
  HANZO_ASSIGN_OR_RETURN(all, versions(map_id));
  if (all.empty()) return Error{fmt::format("map {}: not in the store {}", map_id, location()), "map_id"};
  // Oldest first: a failure part way leaves the newest versions, which load() serves.
  for (const MapVersionInfo& info : all) HANZO_RETURN_IF_ERROR(objects_->remove(version_key(map_id, info.version)));
  HANZO_RETURN_IF_ERROR(objects_->remove_all(prefix_ + map_id + "/"));  // what is left: leftovers of interrupted saves
  logger()->info("map store: deleted {} ({} versions)", map_id, all.size());
  return ok_status();
}

}  // namespace hanzo::fusion::maps
