#pragma once
// Persistent state of the server: sessions (who created them, their configuration and
// calibration), trajectories (every stored PoseEstimate as a timestamped row) and maps (their
// owner and the versions saved; the map files themselves live in a maps::MapStore). Two
// backends with the same schema (docs/server.md lists it):
//
//   open_storage("sqlite:///var/lib/hanzo-fusion/fusion.db")   embedded default: SQLite in WAL
//                                                              mode, synchronous=FULL
//   open_storage("postgresql://user@host:5432/fusion")         scale-out: PostgreSQL (libpq URI);
//                                                              a TimescaleDB hypertable when the
//                                                              extension is available
//
// append_poses() is one transaction: when it returns ok every pose in it is durable (it
// survives kill -9 of the server; with SQLite's synchronous=FULL also a power cut). Poses are
// keyed by (session, timestamp): appending a pose that is already stored keeps the stored one
// (a client that re-sends after a reconnect does not duplicate rows).
//
// Replicas (several servers on one database, docs/server.md "Replicas") coordinate through
// session leases: the replica that serves a session holds its lease and renews it; another
// replica may claim the session once the lease has expired (its holder died or lost the
// database). Claims are atomic: of two replicas claiming one expired lease exactly one wins.
// Lease times are the replicas' wall clocks (keep them synchronized, e.g. by NTP).
//
// Thread-safe: calls are serialized on one connection.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"

namespace hanzo::fusion::service {

struct SessionRecord {
  std::string id;
  std::string organization;
  std::string name;
  std::string config_yaml;       // the FusionConfig the session runs (sensors registered later included)
  std::string calibration_yaml;  // its Calibration
  Timestamp created;
  std::optional<Timestamp> ended;  // set by end_session (DELETE); the trajectory stays queryable
};

struct StoredPose {
  std::string session_id;
  msgs::PoseEstimate estimate;  // timestamp, T_world_body, velocity, covariance, state, active modalities
};

/// How much of a session's trajectory is stored.
struct TrajectoryExtent {
  uint64_t count = 0;
  std::optional<Timestamp> first;  // oldest and newest stored timestamps (none when empty)
  std::optional<Timestamp> last;
};

/// A stored map and who owns it: maps are scoped to the organization that saved or loaded them.
struct MapRecord {
  std::string map_id;
  std::string organization;
  std::string name;
  std::string session_id;  // the session whose map it is; "" for a map loaded by a client (LoadMap)
  Timestamp created;
};

struct MapVersionRecord {
  std::string session_id;
  std::string map_id;
  uint64_t version = 0;
  Timestamp created;
};

/// Which replica serves a session and until when.
struct SessionLease {
  std::string session_id;
  std::string owner;      // the replica's id
  std::string owner_url;  // where the owner answers REST requests, "http://host:port"
  Timestamp expires;      // wall clock; after it another replica may claim the session
};

class Storage {
 public:
  virtual ~Storage() = default;
  virtual std::string_view backend() const = 0;  // "sqlite" or "postgresql"

  /// Fails when the id is taken.
  virtual Status create_session(const SessionRecord& session) = 0;
  /// Replaces the stored configuration and calibration (after a sensor was registered).
  virtual Status update_session_setup(const std::string& id, const std::string& config_yaml,
                                      const std::string& calibration_yaml) = 0;
  virtual Status end_session(const std::string& id, Timestamp ended) = 0;
  /// Every session, ended ones included, oldest first.
  virtual Result<std::vector<SessionRecord>> sessions() = 0;

  /// Stores the poses in one transaction (see above).
  virtual Status append_poses(const std::vector<StoredPose>& poses) = 0;
  /// Poses of a session with timestamp > after, oldest first, at most limit.
  virtual Result<std::vector<msgs::PoseEstimate>> poses(const std::string& session_id, Timestamp after,
                                                        std::size_t limit) = 0;
  virtual Result<TrajectoryExtent> trajectory_extent(const std::string& session_id) = 0;

  /// Claims the session for `owner` until `expires` when nobody holds it, its lease expired
  /// before `now`, or `owner` already holds it; returns the lease as it stands afterwards
  /// (its owner says who holds the session: the claim failed when it is another replica).
  virtual Result<SessionLease> claim_session(const std::string& session_id, const std::string& owner,
                                             const std::string& owner_url, Timestamp now, Timestamp expires) = 0;
  /// Extends to `expires` every lease `owner` still holds (expired ones nobody claimed
  /// included); returns the ids of those sessions.
  virtual Result<std::vector<std::string>> renew_leases(const std::string& owner, Timestamp expires) = 0;
  /// The session's lease; nullopt when no replica ever claimed it or it was released.
  virtual Result<std::optional<SessionLease>> session_lease(const std::string& session_id) = 0;
  /// Hands the lease from `owner` to another replica (`new_owner` at `new_owner_url`, until
  /// `expires`) in one statement, so that no third replica can claim it in between; false when
  /// `owner` does not hold it.
  virtual Result<bool> transfer_session(const std::string& session_id, const std::string& owner, const std::string& new_owner,
                                        const std::string& new_owner_url, Timestamp expires) = 0;
  /// Gives the lease up (the session ended or its owner shuts down); no error when `owner`
  /// does not hold it.
  virtual Status release_session(const std::string& session_id, const std::string& owner) = 0;

  /// Fails when the map id is taken.
  virtual Status create_map(const MapRecord& map) = 0;
  /// Every stored map, oldest first.
  virtual Result<std::vector<MapRecord>> maps() = 0;
  virtual Status record_map_version(const MapVersionRecord& record) = 0;
  /// The versions a session saved, oldest first.
  virtual Result<std::vector<MapVersionRecord>> map_versions(const std::string& session_id) = 0;
  /// Forgets a deleted version (no error when it was not recorded).
  virtual Status delete_map_version(const std::string& map_id, uint64_t version) = 0;
  /// Forgets a deleted map: its owner row and every version row, in one transaction.
  virtual Status delete_map(const std::string& map_id) = 0;
};

/// "sqlite://PATH" (PATH absolute after the two slashes, or relative), a plain file path (SQLite),
/// or "postgresql://..." / "postgres://..." (any libpq connection URI). Creates the schema when
/// missing; fails on a database whose schema version is newer than this program's.
Result<std::unique_ptr<Storage>> open_storage(const std::string& url);

/// The schema version this program writes (the `hanzo_schema` table holds the database's).
/// 1: sessions, trajectory_poses, map_versions; 2: + maps (a version-1 database is upgraded
/// in place: the new table is added); 3: + session_leases (added in place likewise).
inline constexpr int kStorageSchemaVersion = 3;

}  // namespace hanzo::fusion::service
