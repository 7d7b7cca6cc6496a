#pragma once
// ObjectStore: where the server keeps what it stores as whole files (sensor-log recordings,
// map versions). Objects are byte strings under '/'-separated keys ("maps/<id>/0001.fmap"),
// written whole and read whole or by byte range. Two backends behind one interface:
//
//   open_object_store("/var/lib/hanzo-fusion")          local disk (the default): KEY is the
//   open_object_store("file:///var/lib/hanzo-fusion")   file ROOT/KEY, written atomically
//   open_object_store("s3://bucket/prefix")             any S3-compatible store (AWS S3, MinIO,
//                                                       Ceph RGW, s3rver): path-style requests
//                                                       signed with AWS Signature Version 4
//
// S3 settings come from the URL's query and then from the standard AWS environment variables:
//   endpoint  ?endpoint=http://127.0.0.1:9000, else $AWS_ENDPOINT_URL_S3 / $AWS_ENDPOINT_URL,
//             else https://s3.<region>.amazonaws.com
//   region    ?region=eu-west-1, else $AWS_REGION / $AWS_DEFAULT_REGION, else us-east-1
//   keys      $AWS_ACCESS_KEY_ID, $AWS_SECRET_ACCESS_KEY, optional $AWS_SESSION_TOKEN
// Requests go through libcurl (HTTP/1.1, TLS with the system's CA certificates); the signature
// is computed here (libsodium's SHA-256 / HMAC-SHA-256) over the full payload hash. Objects
// larger than S3Config::multipart_threshold_bytes are uploaded in parts (multipart upload),
// so a recording beyond S3's 5 GB single-request limit still stores. Transient failures
// (connection errors, HTTP 429 / 5xx) are retried with exponential back-off.
//
// Consistency: put() replaces an object atomically (readers see the old or the new bytes, on
// disk by rename, on S3 by the service's guarantee). put_if_absent() is the one conditional
// write: link(2) on disk; "If-None-Match: *" on S3, which AWS S3, MinIO and Ceph honour
// (a server that ignores it, like s3rver, makes it a plain put).
//
// Errors name the object and what failed ("s3://bucket/maps/x: GET: HTTP 403
// SignatureDoesNotMatch: ..."); a missing object is an Error whose field is "not_found".
// Thread-safe: every call is independent.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"

namespace hanzo::fusion::object_store {

/// Error::field of an error that means "no such object".
inline constexpr std::string_view kNotFound = "not_found";

struct ObjectInfo {
  std::string key;
  uint64_t size = 0;
  Timestamp modified;  ///< last write, wall-clock time
};

class ObjectStore {
 public:
  virtual ~ObjectStore() = default;

  /// Where the store is: "file:///abs/root" or "s3://bucket/prefix".
  virtual std::string location() const = 0;
  /// Where one object is, for messages and listings ("s3://bucket/prefix/KEY", or its file path).
  virtual std::string location_of(const std::string& key) const = 0;

  /// Stores `bytes` under `key`, replacing what was there.
  virtual Status put(const std::string& key, std::string_view bytes) = 0;
  /// Stores `bytes` only when `key` is free: false (and nothing written) when it is taken.
  virtual Result<bool> put_if_absent(const std::string& key, std::string_view bytes) = 0;
  /// Stores the file at `path` under `key` without reading it into memory.
  virtual Status put_file(const std::string& key, const std::string& path) = 0;

  virtual Result<std::string> get(const std::string& key) const = 0;
  /// Bytes [offset, offset + length) of an object; fewer where it ends sooner.
  virtual Result<std::string> get_range(const std::string& key, uint64_t offset, uint64_t length) const = 0;
  /// Writes the object to `path` (path + ".partial" first, renamed when complete).
  virtual Status get_to_file(const std::string& key, const std::string& path) const = 0;
  /// The object's size and time; empty when there is no such object.
  virtual Result<std::optional<ObjectInfo>> stat(const std::string& key) const = 0;
  /// Every object whose key starts with `prefix`, sorted by key.
  virtual Result<std::vector<ObjectInfo>> list(const std::string& prefix) const = 0;
  /// Deletes an object; deleting a missing object is not an error.
  virtual Status remove(const std::string& key) = 0;
  /// Deletes every object whose key starts with `prefix` (on disk also what interrupted writes
  /// left there). A failure part way leaves the objects not yet deleted.
  virtual Status remove_all(const std::string& prefix) = 0;
};

/// A key is 1..1024 bytes of printable ASCII, without a leading '/', "//", '\\', or a "." or ".."
/// segment (so it can never name a file outside a local store's root).
Status validate_object_key(const std::string& key);

/// A store on the local disk under `root` (created when missing).
Result<std::unique_ptr<ObjectStore>> open_local_object_store(const std::string& root);

struct S3Config {
  std::string endpoint;  ///< scheme://host[:port]; empty: https://s3.<region>.amazonaws.com
  std::string region = "us-east-1";
  std::string bucket;
  std::string prefix;  ///< prepended to every key ("" or ending in '/')
  std::string access_key_id;
  std::string secret_access_key;
  std::string session_token;  ///< temporary credentials (STS); empty otherwise
  /// Objects at least this large are uploaded in parts of part_bytes (S3: 5 MiB .. 5 GiB each).
  uint64_t multipart_threshold_bytes = uint64_t{64} << 20;
  uint64_t part_bytes = uint64_t{16} << 20;
  /// Keys per ListObjectsV2 page (S3 returns at most 1000).
  int list_page_size = 1000;
  /// Attempts per request when it fails transiently (connection error, HTTP 429 or 5xx).
  int max_attempts = 4;
  long connect_timeout_seconds = 10;
  /// A request that moves fewer than 1 KiB/s for this long is abandoned (and retried).
  long stall_timeout_seconds = 60;
};

/// A store in an S3 bucket. Checks the settings (not the connection: the first request does).
Result<std::unique_ptr<ObjectStore>> open_s3_object_store(const S3Config& config);

/// "s3://BUCKET[/PREFIX][?endpoint=URL&region=R]" (settings and keys completed from the
/// environment, see above), "file://PATH" or a plain path (local disk).
Result<std::unique_ptr<ObjectStore>> open_object_store(const std::string& url);
/// Whether `url` names an S3 store (so that callers know a local path is not meant).
bool is_s3_url(std::string_view url);

}  // namespace hanzo::fusion::object_store
