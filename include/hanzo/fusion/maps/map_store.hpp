#pragma once
// A versioned store of FusionMaps (spec: "Each map update is a new version, enabling temporal
// queries ('what did the warehouse look like last Tuesday?')") in an object store: a folder on
// the local disk or an S3 bucket (object_store/object_store.hpp), the same on both.
//
// Layout: <map_id>/<version, 20 digits>.fmap under the store's root (or key prefix), one
// FusionMap file per version. Versions of a map count up from 1 and are never overwritten:
// save() stores the next version with ObjectStore::put_if_absent (link(2) on disk,
// "If-None-Match: *" on S3) and takes the following number when another writer took that one
// first. On disk a crash or kill during a save leaves at most a hidden temporary file, which
// readers ignore; every version that save() reported stays readable until remove_version() /
// remove_map() deletes it (retention, or a client's request).
//
// Encryption at rest: with MapStoreConfig::encryption_key every saved version is encrypted
// (crypto/file_encryption.hpp: XChaCha20-Poly1305, the key's id in the header); stored
// versions are decrypted with whichever of the configured keys their header names, so versions
// written before a key rotation stay readable while their key is listed. A tampered or
// truncated version is refused, naming it. Plain and encrypted versions may sit side by side.
//
// Listing reads each version's metadata (its first chunk, a ranged read) once per MapStore and
// remembers it: versions never change once stored.
//
// map ids are 1..128 characters of [A-Za-z0-9._-], not starting with '.', so that an id can
// never name a path outside the store.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/crypto/file_encryption.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/object_store/object_store.hpp"

namespace hanzo::fusion::maps {

struct MapVersionInfo {
  std::string map_id;
  uint64_t version = 0;
  uint64_t parent_version = 0;
  Timestamp created;
  uint64_t file_bytes = 0;  ///< bytes stored (encrypted size when encrypted)
  std::string location;     ///< the file's path, or its s3:// URL
  std::string key_id;       ///< id of the key it is encrypted with; empty when stored in plain
  /// Why its metadata cannot be read (a damaged file, a key not given); empty when it can.
  /// Such a version is listed (with created 0), never chosen by load_at, and load() refuses it.
  std::string unreadable;
};

struct MapStoreConfig {
  FusionMapFileConfig file;
  /// Versions are saved encrypted with this key; none: saved as plain FusionMap files.
  std::optional<crypto::EncryptionKey> encryption_key;
  /// Further keys that stored versions may name (keys retired by a rotation).
  std::vector<crypto::EncryptionKey> decryption_keys;
};

/// A random version-4 UUID ("xxxxxxxx-xxxx-4xxx-yxxx-xxxxxxxxxxxx").
std::string generate_map_id();
/// Fails naming the rule an id breaks.
Status validate_map_id(const std::string& map_id);

class MapStore {
 public:
  /// Opens a store: a folder (created when missing), "file://PATH" or "s3://bucket/prefix"
  /// (object_store::open_object_store).
  static Result<MapStore> open(const std::string& url, MapStoreConfig config = {});
  /// A store under `key_prefix` ("" or ending in '/') of an object store shared with others.
  MapStore(std::shared_ptr<object_store::ObjectStore> objects, std::string key_prefix, MapStoreConfig config = {});

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
  /// The FusionMap file of a version (decrypted when stored encrypted), without decoding it; the
  /// latest when `version` is empty. Also returns the version.
  Result<std::pair<uint64_t, std::string>> file(const std::string& map_id, std::optional<uint64_t> version = std::nullopt) const;

  /// Deletes one stored version of a map. The newest version cannot be deleted alone (save()
  /// numbers after the newest file, so its number would be given again): delete the map.
  /// Fails naming the map and version (unknown version, newest version, file system error).
  Status remove_version(const std::string& map_id, uint64_t version);
  /// Deletes a map: every version and its folder. A failure part way leaves the versions not
  /// yet deleted readable (delete again).
  Status remove_map(const std::string& map_id);

  /// Where the store is ("file:///..." or "s3://...").
  std::string location() const;

 private:
  struct MetadataCache;
  std::string version_key(const std::string& map_id, uint64_t version) const;
  Result<MapVersionInfo> read_version_info(const object_store::ObjectInfo& object, const std::string& map_id, uint64_t version) const;
  Result<std::string> read_plaintext(const MapVersionInfo& info) const;
  Result<const MapVersionInfo*> find_version(const std::vector<MapVersionInfo>& all, const std::string& map_id,
                                             std::optional<uint64_t> version) const;

  std::shared_ptr<object_store::ObjectStore> objects_;
  std::string prefix_;
  MapStoreConfig config_;
  std::vector<crypto::EncryptionKey> keys_;  // every key that may decrypt a version
  std::shared_ptr<MetadataCache> cache_;
};

}  // namespace hanzo::fusion::maps
