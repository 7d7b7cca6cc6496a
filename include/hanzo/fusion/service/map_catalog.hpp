#pragma once
// MapCatalog: the server's stored maps. Each map is a series of versions in a maps::MapStore
// (the server's DATA_DIR/maps, or maps/ in its S3 bucket: one FusionMap file per version, never
// overwritten, encrypted when the server has an encryption key); who
// owns a map is a row of the Storage's `maps` table and every saved version a row of
// `map_versions`, so SQL users can list them next to the sessions.
//
// A map belongs to the organization that first saved it: a session's map (map_id = the
// session id, saved while the session runs and when it ends) or a map a client loaded
// (gRPC LoadMap, REST POST /v1/maps). Saving under an id of another organization's map, or
// reading one, is kPermissionDenied; an unknown id or version is kNotFound; an invalid id is
// kInvalidArgument. The caller checks permissions (map:read / map:write) and that a client's
// map passes msgs::validate (SessionManager; LoadMap and POST /v1/maps decode and validate it).
//
// Thread-safe.

#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <shared_mutex>
#include <string>
#include <vector>

#include "hanzo/fusion/maps/map_store.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/service/api_error.hpp"
#include "hanzo/fusion/service/storage.hpp"

namespace hanzo::fusion::service {

struct StoredMap {
  MapRecord record;
  std::vector<maps::MapVersionInfo> versions;  // oldest first
};

class MapCatalog {
 public:
  /// The maps of `store` with the owners `storage` lists. `storage` must outlive the catalog.
  static Result<std::unique_ptr<MapCatalog>> open(maps::MapStore store, Storage& storage);

  /// Stores `map` as the next version of map.map_id (a new UUID when empty), owned by
  /// `organization` when the id is new (`session_id`, `name` describe it then). The stored
  /// version's parent is map.version when the store has that version (a map that was loaded,
  /// edited and loaded again), else 0.
  ApiResult<maps::MapVersionInfo> save(const std::string& organization, const std::string& session_id, const std::string& name,
                                       msgs::FusionMap map);
  /// A stored version (the latest when `version` is empty) of a map of `organization`.
  ApiResult<msgs::FusionMap> load(const std::string& organization, const std::string& map_id,
                                  std::optional<uint64_t> version = std::nullopt) const;
  /// The FusionMap file of a stored version (the latest when `version` is empty; decrypted when
  /// stored encrypted): served without decoding it. Also returns the version.
  ApiResult<std::pair<uint64_t, std::string>> file(const std::string& organization, const std::string& map_id,
                                                   std::optional<uint64_t> version = std::nullopt) const;
  /// The maps of `organization`, oldest first, each with its versions.
  ApiResult<std::vector<StoredMap>> list(const std::string& organization) const;
  ApiResult<StoredMap> find(const std::string& organization, const std::string& map_id) const;

  /// Deletes a map of `organization` with every version (and its rows), or only `version`.
  /// kNotFound: unknown map or version; kConflict: `version` is the map's newest (version
  /// numbers are never given twice; delete the map instead); kInternal: a file system or
  /// database failure (what was deleted before it stays deleted). Returns the number of
  /// versions deleted.
  ApiResult<std::size_t> remove(const std::string& organization, const std::string& map_id, std::optional<uint64_t> version);
  /// Retention: deletes all but the newest `keep` (>= 1) versions of `map_id`; returns how many
  /// it deleted.
  Result<std::size_t> prune(const std::string& map_id, std::size_t keep);

 private:
  MapCatalog(maps::MapStore store, Storage& storage) : store_(std::move(store)), storage_(storage) {}
  // The owner record of `map_id` when `organization` may use it; caller holds mutex_.
  ApiResult<MapRecord> owned_locked(const std::string& organization, const std::string& map_id) const;

  maps::MapStore store_;
  Storage& storage_;
  mutable std::mutex mutex_;
  std::map<std::string, MapRecord> owners_;  // map_id -> owner
  // Saves write files under a shared lock, a map's deletion holds it exclusively (a save never
  // recreates a map that is being deleted).
  std::shared_mutex files_mutex_;
};

}  // namespace hanzo::fusion::service
