#include "hanzo/fusion/service/map_catalog.hpp"

#include <algorithm>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::service {

Result<std::unique_ptr<MapCatalog>> MapCatalog::open(maps::MapStore store, Storage& storage) {
  std::vector<MapRecord> records;
  HANZO_ASSIGN_OR_RETURN(records, storage.maps());
  const std::string location = store.location();
  std::unique_ptr<MapCatalog> catalog(new MapCatalog(std::move(store), storage));
  for (MapRecord& record : records) catalog->owners_.emplace(record.map_id, std::move(record));
  logger()->info("maps: {} stored maps in {}", catalog->owners_.size(), location);
  return catalog;
}

ApiResult<MapRecord> MapCatalog::owned_locked(const std::string& organization, const std::string& map_id) const {
  const auto found = owners_.find(map_id);
  if (found == owners_.end()) return ApiError{ErrorCode::kNotFound, fmt::format("no map '{}'", map_id), "map_id"};
  if (found->second.organization != organization) {
    return ApiError{ErrorCode::kPermissionDenied, fmt::format("map '{}' belongs to another organization", map_id), "map_id"};
  }
  return found->second;
}

ApiResult<maps::MapVersionInfo> MapCatalog::save(const std::string& organization, const std::string& session_id, const std::string& name,
                                                 msgs::FusionMap map) {
  if (map.map_id.empty()) map.map_id = maps::generate_map_id();
  if (const Status valid = maps::validate_map_id(map.map_id); !valid) {
    return ApiError{ErrorCode::kInvalidArgument, "map_id: " + valid.error().message, "map_id"};
  }
  {
    std::lock_guard lock(mutex_);
    if (!owners_.contains(map.map_id)) {
      const MapRecord record{map.map_id, organization, name.empty() ? map.map_id : name, session_id, Timestamp::wall_clock_now()};
      if (const Status stored = storage_.create_map(record); !stored) return ApiError::from(ErrorCode::kInternal, stored.error());
      owners_.emplace(record.map_id, record);
    } else if (auto owned = owned_locked(organization, map.map_id); !owned) {
      return owned.error();
    }
  }
  // The file is written outside the lock: MapStore takes the next free version itself.
  std::shared_lock files(files_mutex_);
  {
    std::lock_guard lock(mutex_);  // deleted while we waited for the files
    if (!owners_.contains(map.map_id)) return ApiError{ErrorCode::kConflict, fmt::format("map '{}' was deleted meanwhile", map.map_id), "map_id"};
  }
  Result<maps::MapVersionInfo> saved = store_.save(std::move(map));
  if (!saved) return ApiError::from(ErrorCode::kInternal, saved.error());
  if (const Status recorded = storage_.record_map_version({session_id, saved->map_id, saved->version, saved->created}); !recorded) {
    // The version is stored (its file is the source of truth); only the index row is missing.
    logger()->warn("maps: version {} of map {} stored, but not recorded in the database: {}", saved->version, saved->map_id,
                   recorded.error().message);
  }
  return std::move(saved).value();
}

ApiResult<msgs::FusionMap> MapCatalog::load(const std::string& organization, const std::string& map_id,
                                            std::optional<uint64_t> version) const {
  {
    std::lock_guard lock(mutex_);
    if (auto owned = owned_locked(organization, map_id); !owned) return owned.error();
  }
  Result<msgs::FusionMap> map = store_.load(map_id, version);
  if (!map) {
    if (map.error().field == "map_id" || map.error().field == "version") {
      return ApiError{ErrorCode::kNotFound,
                      version ? fmt::format("map '{}' has no version {}", map_id, *version) : fmt::format("map '{}' has no stored version", map_id),
                      "version"};
    }
    return ApiError::from(ErrorCode::kInternal, map.error());  // unreadable: the reason (a damaged file, a missing key) says why
  }
  return std::move(map).value();
}

ApiResult<std::pair<uint64_t, std::string>> MapCatalog::file(const std::string& organization, const std::string& map_id,
                                                             std::optional<uint64_t> version) const {
  {
    std::lock_guard lock(mutex_);
    if (auto owned = owned_locked(organization, map_id); !owned) return owned.error();
  }
  Result<std::pair<uint64_t, std::string>> file = store_.file(map_id, version);
  if (!file) {
    if (file.error().field == "map_id" || file.error().field == "version") {
      return ApiError{ErrorCode::kNotFound,
                      version ? fmt::format("map '{}' has no version {}", map_id, *version) : fmt::format("map '{}' has no stored version", map_id),
                      "version"};
    }
    return ApiError::from(ErrorCode::kInternal, file.error());
  }
  return std::move(file).value();
}

ApiResult<StoredMap> MapCatalog::find(const std::string& organization, const std::string& map_id) const {
  StoredMap stored;
  {
    std::lock_guard lock(mutex_);
    auto owned = owned_locked(organization, map_id);
    if (!owned) return owned.error();
    stored.record = std::move(owned).value();
  }
  Result<std::vector<maps::MapVersionInfo>> versions = store_.versions(map_id);
  if (versions) stored.versions = std::move(versions).value();  // none yet when the first save failed
  return stored;
}

ApiResult<std::vector<StoredMap>> MapCatalog::list(const std::string& organization) const {
  std::vector<std::string> ids;
  {
    std::lock_guard lock(mutex_);
    std::vector<const MapRecord*> records;
    for (const auto& [id, record] : owners_) {
      if (record.organization == organization) records.push_back(&record);
    }
    std::sort(records.begin(), records.end(), [](const MapRecord* a, const MapRecord* b) {
      return a->created != b->created ? a->created < b->created : a->map_id < b->map_id;
    });
    for (const MapRecord* record : records) ids.push_back(record->map_id);
  }
  std::vector<StoredMap> maps;
  for (const std::string& id : ids) {
    auto stored = find(organization, id);
    if (stored) maps.push_back(std::move(stored).value());
  }
  return maps;
}

ApiResult<std::size_t> MapCatalog::remove(const std::string& organization, const std::string& map_id, std::optional<uint64_t> version) {
  auto stored = find(organization, map_id);
  if (!stored) return stored.error();
  if (version) {
    const auto& versions = stored->versions;
    if (std::none_of(versions.begin(), versions.end(), [&](const maps::MapVersionInfo& v) { return v.version == *version; })) {
      return ApiError{ErrorCode::kNotFound, fmt::format("map '{}' has no version {}", map_id, *version), "version"};
    }
    if (*version == versions.back().version) {
      return ApiError{ErrorCode::kConflict,
                      fmt::format("version {} is the newest of map '{}': delete the map, or save a newer version first", *version, map_id),
                      "version"};
    }
    std::shared_lock files(files_mutex_);
    if (const Status removed = store_.remove_version(map_id, *version); !removed) return ApiError::from(ErrorCode::kInternal, removed.error());
    if (const Status forgotten = storage_.delete_map_version(map_id, *version); !forgotten) {
      logger()->warn("maps: version {} of map {} deleted, but still in the database: {}", *version, map_id, forgotten.error().message);
    }
    return std::size_t{1};
  }
  std::unique_lock files(files_mutex_);
  if (!stored->versions.empty()) {
    if (const Status removed = store_.remove_map(map_id); !removed) return ApiError::from(ErrorCode::kInternal, removed.error());
  }
  if (const Status forgotten = storage_.delete_map(map_id); !forgotten) return ApiError::from(ErrorCode::kInternal, forgotten.error());
  std::lock_guard lock(mutex_);
  owners_.erase(map_id);
  logger()->info("maps: map {} deleted", map_id);
  return stored->versions.size();
}

Result<std::size_t> MapCatalog::prune(const std::string& map_id, std::size_t keep) {
  if (keep == 0) return Error("prune: keep must be at least 1");
  std::shared_lock files(files_mutex_);
  std::vector<maps::MapVersionInfo> versions;
  HANZO_ASSIGN_OR_RETURN(versions, store_.versions(map_id));
  std::size_t removed = 0;
  for (std::size_t i = 0; i + keep < versions.size(); ++i) {
    HANZO_RETURN_IF_ERROR(store_.remove_version(map_id, versions[i].version));
    if (const Status forgotten = storage_.delete_map_version(map_id, versions[i].version); !forgotten) {
      logger()->warn("maps: version {} of map {} deleted, but still in the database: {}", versions[i].version, map_id,
                     forgotten.error().message);
    }
    ++removed;
  }
  return removed;
}

}  // namespace hanzo::fusion::service
