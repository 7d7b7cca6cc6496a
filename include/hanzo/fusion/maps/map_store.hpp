#pragma once
// A versioned store of FusionMaps in a folder (spec: "Each map update is a new version,
// enabling temporal queries ('what did the warehouse look like last Tuesday?')").
//
// Layout: ROOT/<map_id>/<version, 20 digits>.fmap, one FusionMap file per version. Versions
// of a map count up from 1 and are never overwritten: save() writes the new version to a
// temporary file, fsyncs it and links it under its final name with link(2), which fails if
// another writer took that version first (save() then takes the next one). A crash or kill
// during a save leaves at most a stray hidden ".<pid>-<uuid>.tmp" file, which readers ignore;
// every version that save() reported stays readable until remove_version() / remove_map()
// deletes it (retention, or a client's request).
//
// map ids are 1..128 characters of [A-Za-z0-9._-], not starting with '.', so that an id can
// never name a path outside the store.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct MapVersionInfo {
  std::string map_id;
  uint64_t version = 0;
  uint64_t parent_version = 0;
  Timestamp created;
  uint64_t file_bytes = 0;
  std::string path;
};

/// A random version-4 UUID ("xxxxxxxx-xxxx-4xxx-yxxx-xxxxxxxxxxxx").
std::string generate_map_id();
/// Fails naming the rule an id breaks.
Status validate_map_id(const std::string& map_id);

class MapStore {
 public:
  /// Opens (creating when missing) the store folder `root`.
  static Result<MapStore> open(const std::string& root, const FusionMapFileConfig& file_config = {});

  /// Saves `map` as the next version of its map_id (a new UUID when empty) and returns what
  /// was stored. The stored map gets version = latest + 1, parent_version = map.version when
  /// that version is in the store (the version it was loaded as), else 0, and, when
  /// map.created is 0, the current time.
  Result<MapVersionInfo> save(msgs::FusionMap map);

  /// Every map id in the store, sorted.
  Result<std::vector<std::string>> map_ids() const;
  /// The versions of `map_id`, oldest first (metadata only: no layer is decoded).
  Result<std::vector<MapVersionInfo>> versions(const std::string& map_id) const;
  /// A version of a map; the latest when `version` is empty.
  Result<msgs::FusionMap> load(const std::string& map_id, std::optional<uint64_t> version = std::nullopt) const;
  /// The newest version created at or before `time`.
  Result<msgs::FusionMap> load_at(const std::string& map_id, Timestamp time) const;

  /// Deletes one stored version of a map. The newest version cannot be deleted alone (save()
  /// numbers after the newest file, so its number would be given again): delete the map.
  /// Fails naming the map and version (unknown version, newest version, file system error).
  Status remove_version(const std::string& map_id, uint64_t version);
  /// Deletes a map: every version and its folder. A failure part way leaves the versions not
  /// yet deleted readable (delete again).
  Status remove_map(const std::string& map_id);

  const std::string& root() const { return root_; }

 private:
  MapStore(std::string root, FusionMapFileConfig file_config) : root_(std::move(root)), file_config_(file_config) {}
  std::string version_path(const std::string& map_id, uint64_t version) const;

  std::string root_;
  FusionMapFileConfig file_config_;
};

}  // namespace hanzo::fusion::maps
