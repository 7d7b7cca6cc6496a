// Storage on SQLite (the embedded default): one database file in WAL mode.
#include <sqlite3.h>

#include <filesystem>
#include <mutex>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "pose_rows.hpp"
#include "storage_backends.hpp"

namespace hanzo::fusion::service::detail {
namespace {

constexpr const char* kSchema = R"sql(
CREATE TABLE IF NOT EXISTS hanzo_schema (version INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS sessions (
  id TEXT PRIMARY KEY,
  organization TEXT NOT NULL,
  name TEXT NOT NULL,
  config_yaml TEXT NOT NULL,
  calibration_yaml TEXT NOT NULL,
  created_ns INTEGER NOT NULL,
  ended_ns INTEGER
);
CREATE TABLE IF NOT EXISTS trajectory_poses (
  session_id TEXT NOT NULL,
  timestamp_ns INTEGER NOT NULL,
  x REAL NOT NULL, y REAL NOT NULL, z REAL NOT NULL,
  qw REAL NOT NULL, qx REAL NOT NULL, qy REAL NOT NULL, qz REAL NOT NULL,
  vx REAL NOT NULL, vy REAL NOT NULL, vz REAL NOT NULL,
  state TEXT NOT NULL,
  active_sensors TEXT NOT NULL,
  covariance BLOB,
  PRIMARY KEY (session_id, timestamp_ns)
) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS map_versions (
  session_id TEXT NOT NULL,
  map_id TEXT NOT NULL,
  version INTEGER NOT NULL,
  created_ns INTEGER NOT NULL,
  PRIMARY KEY (map_id, version)
);
CREATE INDEX IF NOT EXISTS map_versions_by_session ON map_versions (session_id);
CREATE TABLE IF NOT EXISTS maps (
  map_id TEXT PRIMARY KEY,
  organization TEXT NOT NULL,
  name TEXT NOT NULL,
  session_id TEXT NOT NULL,
  created_ns INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS session_leases (
  session_id TEXT PRIMARY KEY,
  owner TEXT NOT NULL,
  owner_url TEXT NOT NULL,
  expires_ns INTEGER NOT NULL
);
)sql";

// A prepared statement, finalized on destruction.
class Statement {
 public:
  Statement(sqlite3* database, const char* sql) : database_(database) {
    if (sqlite3_prepare_v2(database, sql, -1, &statement_, nullptr) != SQLITE_OK) statement_ = nullptr;
  }
  ~Statement() { sqlite3_finalize(statement_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  bool prepared() const { return statement_ != nullptr; }
  Statement& bind(int index, std::string_view text) {
    sqlite3_bind_text(statement_, index, text.data(), static_cast<int>(text.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Statement& bind(int index, int64_t value) {
    sqlite3_bind_int64(statement_, index, value);
    return *this;
  }
  Statement& bind(int index, double value) {
    sqlite3_bind_double(statement_, index, value);
    return *this;
  }
  Statement& bind_blob(int index, std::string_view bytes) {
    sqlite3_bind_blob(statement_, index, bytes.data(), static_cast<int>(bytes.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Statement& bind_null(int index) {
    sqlite3_bind_null(statement_, index);
    return *this;
  }
  /// SQLITE_ROW, SQLITE_DONE or an error code.
  int step() { return sqlite3_step(statement_); }
  void reset() {
    sqlite3_reset(statement_);
    sqlite3_clear_bindings(statement_);
  }
  int64_t integer(int column) const { return sqlite3_column_int64(statement_, column); }
  double real(int column) const { return sqlite3_column_double(statement_, column); }
  bool is_null(int column) const { return sqlite3_column_type(statement_, column) == SQLITE_NULL; }
  std::string text(int column) const {
    const auto* bytes = sqlite3_column_text(statement_, column);
    return bytes == nullptr ? std::string() : std::string(reinterpret_cast<const char*>(bytes));
  }
  std::string_view blob(int column) const {
    const auto* bytes = static_cast<const char*>(sqlite3_column_blob(statement_, column));
    return {bytes, static_cast<std::size_t>(sqlite3_column_bytes(statement_, column))};
  }

 private:
  sqlite3* database_;
  sqlite3_stmt* statement_ = nullptr;
};

class SqliteStorage final : public Storage {
 public:
  explicit SqliteStorage(sqlite3* database, std::string path) : database_(database), path_(std::move(path)) {}
  ~SqliteStorage() override { sqlite3_close_v2(database_); }

  std::string_view backend() const override { return "sqlite"; }

  Status initialize() {
    HANZO_RETURN_IF_ERROR(execute("PRAGMA journal_mode=WAL"));
    HANZO_RETURN_IF_ERROR(execute("PRAGMA synchronous=FULL"));
    HANZO_RETURN_IF_ERROR(execute("PRAGMA foreign_keys=ON"));
    sqlite3_busy_timeout(database_, 10000);
    HANZO_RETURN_IF_ERROR(execute(kSchema));
    Statement version(database_, "SELECT version FROM hanzo_schema");
    if (!version.prepared()) return failure("read the schema version");
    if (version.step() == SQLITE_ROW) {
      const int64_t stored = version.integer(0);
      if (stored > kStorageSchemaVersion) {
        return Error(fmt::format("{}: database schema version {} is newer than this program's ({}); upgrade hanzo-fusion",
                                 path_, stored, kStorageSchemaVersion));
      }
      if (stored < kStorageSchemaVersion) {  // the schema above added what is new
        return execute(fmt::format("UPDATE hanzo_schema SET version = {}", kStorageSchemaVersion));
      }
      return ok_status();
    }
    return execute(fmt::format("INSERT INTO hanzo_schema (version) VALUES ({})", kStorageSchemaVersion));
  }

  Status create_session(const SessionRecord& session) override {
    std::lock_guard lock(mutex_);
    Statement insert(database_,
                     "INSERT INTO sessions (id, organization, name, config_yaml, calibration_yaml, created_ns, ended_ns) "
                     "VALUES (?, ?, ?, ?, ?, ?, ?)");
    insert.bind(1, session.id).bind(2, session.organization).bind(3, session.name).bind(4, session.config_yaml);
    insert.bind(5, session.calibration_yaml).bind(6, session.created.nanoseconds());
    if (session.ended) insert.bind(7, session.ended->nanoseconds());
    else insert.bind_null(7);
    if (insert.step() != SQLITE_DONE) return failure(fmt::format("store session '{}'", session.id));
    return ok_status();
  }

  Status update_session_setup(const std::string& id, const std::string& config_yaml,
                              const std::string& calibration_yaml) override {
    std::lock_guard lock(mutex_);
    Statement update(database_, "UPDATE sessions SET config_yaml = ?, calibration_yaml = ? WHERE id = ?");
    update.bind(1, config_yaml).bind(2, calibration_yaml).bind(3, id);
    if (update.step() != SQLITE_DONE) return failure(fmt::format("update session '{}'", id));
    if (sqlite3_changes(database_) != 1) return Error(fmt::format("session '{}' is not stored", id));
    return ok_status();
  }

  Status end_session(const std::string& id, Timestamp ended) override {
    std::lock_guard lock(mutex_);
    Statement update(database_, "UPDATE sessions SET ended_ns = ? WHERE id = ?");
    update.bind(1, ended.nanoseconds()).bind(2, id);
    if (update.step() != SQLITE_DONE) return failure(fmt::format("end session '{}'", id));
    if (sqlite3_changes(database_) != 1) return Error(fmt::format("session '{}' is not stored", id));
    return ok_status();
  }

  Result<std::vector<SessionRecord>> sessions() override {
    std::lock_guard lock(mutex_);
    Statement query(database_,
                    "SELECT id, organization, name, config_yaml, calibration_yaml, created_ns, ended_ns FROM sessions "
                    "ORDER BY created_ns, id");
    std::vector<SessionRecord> records;
    int code = SQLITE_ERROR;
    while ((code = query.step()) == SQLITE_ROW) {
      SessionRecord& record = records.emplace_back();
      record.id = query.text(0);
      record.organization = query.text(1);
      record.name = query.text(2);
      record.config_yaml = query.text(3);
      record.calibration_yaml = query.text(4);
      record.created = Timestamp::from_nanoseconds(query.integer(5));
      if (!query.is_null(6)) record.ended = Timestamp::from_nanoseconds(query.integer(6));
    }
    if (code != SQLITE_DONE) return failure("list sessions");
    return records;
  }

  Status append_poses(const std::vector<StoredPose>& poses) override {
    if (poses.empty()) return ok_status();
    std::lock_guard lock(mutex_);
    HANZO_RETURN_IF_ERROR(execute("BEGIN IMMEDIATE"));
    Statement insert(database_,
                     "INSERT OR IGNORE INTO trajectory_poses (session_id, timestamp_ns, x, y, z, qw, qx, qy, qz, vx, vy, vz, "
                     "state, active_sensors, covariance) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)");
    for (const StoredPose& pose : poses) {
      const msgs::PoseEstimate& estimate = pose.estimate;
      insert.bind(1, pose.session_id).bind(2, estimate.timestamp.nanoseconds());
      const Eigen::Vector3d& p = estimate.T_world_body.position;
      const Eigen::Quaterniond& q = estimate.T_world_body.orientation;
      insert.bind(3, p.x()).bind(4, p.y()).bind(5, p.z()).bind(6, q.w()).bind(7, q.x()).bind(8, q.y()).bind(9, q.z());
      insert.bind(10, estimate.velocity.x()).bind(11, estimate.velocity.y()).bind(12, estimate.velocity.z());
      insert.bind(13, msgs::to_string(estimate.status.state)).bind(14, join_sensors(estimate.status.active_sensors));
      if (estimate.pose_covariance) insert.bind_blob(15, encode_covariance(*estimate.pose_covariance));
      else insert.bind_null(15);
      if (insert.step() != SQLITE_DONE) {
        Error error = failure(fmt::format("store a pose of session '{}'", pose.session_id));
        (void)execute("ROLLBACK");
        return error;
      }
      insert.reset();
    }
    return execute("COMMIT");
  }

  Result<std::vector<msgs::PoseEstimate>> poses(const std::string& session_id, Timestamp after, std::size_t limit) override {
    std::lock_guard lock(mutex_);
    Statement query(database_,
                    "SELECT timestamp_ns, x, y, z, qw, qx, qy, qz, vx, vy, vz, state, active_sensors, covariance "
                    "FROM trajectory_poses WHERE session_id = ? AND timestamp_ns > ? ORDER BY timestamp_ns LIMIT ?");
    query.bind(1, session_id).bind(2, after.nanoseconds()).bind(3, static_cast<int64_t>(limit));
    std::vector<msgs::PoseEstimate> estimates;
    int code = SQLITE_ERROR;
    while ((code = query.step()) == SQLITE_ROW) {
      msgs::PoseEstimate& estimate = estimates.emplace_back();
      estimate.timestamp = Timestamp::from_nanoseconds(query.integer(0));
      estimate.frame_id = msgs::kWorldFrame;
      estimate.child_frame_id = msgs::kBodyFrame;
      estimate.T_world_body.position = {query.real(1), query.real(2), query.real(3)};
      estimate.T_world_body.orientation = Eigen::Quaterniond(query.real(4), query.real(5), query.real(6), query.real(7));
      estimate.velocity = {query.real(8), query.real(9), query.real(10)};
      estimate.status.state = tracking_state_from_name(query.text(11));
      estimate.status.active_sensors = split_sensors(query.text(12));
      estimate.status.active_modalities = static_cast<uint32_t>(estimate.status.active_sensors.size());
      if (!query.is_null(13)) estimate.pose_covariance = decode_covariance(query.blob(13));
    }
    if (code != SQLITE_DONE) return failure(fmt::format("read the trajectory of session '{}'", session_id));
    return estimates;
  }

  Result<TrajectoryExtent> trajectory_extent(const std::string& session_id) override {
    std::lock_guard lock(mutex_);
    Statement query(database_, "SELECT COUNT(*), MIN(timestamp_ns), MAX(timestamp_ns) FROM trajectory_poses WHERE session_id = ?");
    query.bind(1, session_id);
    if (query.step() != SQLITE_ROW) return failure(fmt::format("count the poses of session '{}'", session_id));
    TrajectoryExtent extent;
    extent.count = static_cast<uint64_t>(query.integer(0));
    if (!query.is_null(1)) extent.first = Timestamp::from_nanoseconds(query.integer(1));
    if (!query.is_null(2)) extent.last = Timestamp::from_nanoseconds(query.integer(2));
    return extent;
  }

  Result<SessionLease> claim_session(const std::string& session_id, const std::string& owner, const std::string& owner_url,
                                     Timestamp now, Timestamp expires) override {
    std::lock_guard lock(mutex_);
    Statement claim(database_,
                    "INSERT INTO session_leases (session_id, owner, owner_url, expires_ns) VALUES (?, ?, ?, ?) "
                    "ON CONFLICT (session_id) DO UPDATE SET owner = excluded.owner, owner_url = excluded.owner_url, "
                    "expires_ns = excluded.expires_ns WHERE session_leases.expires_ns < ? OR session_leases.owner = excluded.owner");
    claim.bind(1, session_id).bind(2, owner).bind(3, owner_url).bind(4, expires.nanoseconds()).bind(5, now.nanoseconds());
    if (claim.step() != SQLITE_DONE) return failure(fmt::format("claim session '{}'", session_id));
    std::optional<SessionLease> lease;
    HANZO_ASSIGN_OR_RETURN(lease, lease_locked(session_id));
    if (!lease) return Error(fmt::format("{}: the lease of session '{}' vanished while it was claimed", path_, session_id));
    return *lease;
  }

  Result<std::vector<std::string>> renew_leases(const std::string& owner, Timestamp expires) override {
    std::lock_guard lock(mutex_);
    Statement renew(database_, "UPDATE session_leases SET expires_ns = ? WHERE owner = ? RETURNING session_id");
    renew.bind(1, expires.nanoseconds()).bind(2, owner);
    std::vector<std::string> held;
    int code = SQLITE_ERROR;
    while ((code = renew.step()) == SQLITE_ROW) held.push_back(renew.text(0));
    if (code != SQLITE_DONE) return failure("renew session leases");
    return held;
  }

  Result<std::optional<SessionLease>> session_lease(const std::string& session_id) override {
    std::lock_guard lock(mutex_);
    return lease_locked(session_id);
  }

  Result<bool> transfer_session(const std::string& session_id, const std::string& owner, const std::string& new_owner,
                                const std::string& new_owner_url, Timestamp expires) override {
    std::lock_guard lock(mutex_);
    Statement transfer(database_, "UPDATE session_leases SET owner = ?, owner_url = ?, expires_ns = ? WHERE session_id = ? AND owner = ?");
    transfer.bind(1, new_owner).bind(2, new_owner_url).bind(3, expires.nanoseconds()).bind(4, session_id).bind(5, owner);
    if (transfer.step() != SQLITE_DONE) return failure(fmt::format("hand session '{}' over", session_id));
    return sqlite3_changes(database_) == 1;
  }

  Status release_session(const std::string& session_id, const std::string& owner) override {
    std::lock_guard lock(mutex_);
    Statement release(database_, "DELETE FROM session_leases WHERE session_id = ? AND owner = ?");
    release.bind(1, session_id).bind(2, owner);
    if (release.step() != SQLITE_DONE) return failure(fmt::format("release session '{}'", session_id));
    return ok_status();
  }

  Status create_map(const MapRecord& map) override {
    std::lock_guard lock(mutex_);
    Statement insert(database_, "INSERT INTO maps (map_id, organization, name, session_id, created_ns) VALUES (?, ?, ?, ?, ?)");
    insert.bind(1, map.map_id).bind(2, map.organization).bind(3, map.name).bind(4, map.session_id);
    insert.bind(5, map.created.nanoseconds());
    if (insert.step() != SQLITE_DONE) return failure(fmt::format("store map '{}'", map.map_id));
    return ok_status();
  }

  Result<std::vector<MapRecord>> maps() override {
    std::lock_guard lock(mutex_);
    Statement query(database_, "SELECT map_id, organization, name, session_id, created_ns FROM maps ORDER BY created_ns, map_id");
    std::vector<MapRecord> records;
    int code = SQLITE_ERROR;
    while ((code = query.step()) == SQLITE_ROW) {
      records.push_back({query.text(0), query.text(1), query.text(2), query.text(3), Timestamp::from_nanoseconds(query.integer(4))});
    }
    if (code != SQLITE_DONE) return failure("list maps");
    return records;
  }

  Status record_map_version(const MapVersionRecord& record) override {
    std::lock_guard lock(mutex_);
    Statement insert(database_, "INSERT INTO map_versions (session_id, map_id, version, created_ns) VALUES (?, ?, ?, ?)");
    insert.bind(1, record.session_id).bind(2, record.map_id).bind(3, static_cast<int64_t>(record.version));
    insert.bind(4, record.created.nanoseconds());
    if (insert.step() != SQLITE_DONE) return failure(fmt::format("record map {} version {}", record.map_id, record.version));
    return ok_status();
  }

  Result<std::vector<MapVersionRecord>> map_versions(const std::string& session_id) override {
    std::lock_guard lock(mutex_);
    Statement query(database_,
                    "SELECT map_id, version, created_ns FROM map_versions WHERE session_id = ? ORDER BY created_ns, version");
    query.bind(1, session_id);
    std::vector<MapVersionRecord> records;
    int code = SQLITE_ERROR;
    while ((code = query.step()) == SQLITE_ROW) {
      records.push_back({session_id, query.text(0), static_cast<uint64_t>(query.integer(1)),
                         Timestamp::from_nanoseconds(query.integer(2))});
    }
    if (code != SQLITE_DONE) return failure("list map versions");
    return records;
  }

  Status delete_map_version(const std::string& map_id, uint64_t version) override {
    std::lock_guard lock(mutex_);
    Statement erase(database_, "DELETE FROM map_versions WHERE map_id = ? AND version = ?");
    erase.bind(1, map_id).bind(2, static_cast<int64_t>(version));
    if (erase.step() != SQLITE_DONE) return failure(fmt::format("forget map {} version {}", map_id, version));
    return ok_status();
  }

  Status delete_map(const std::string& map_id) override {
    std::lock_guard lock(mutex_);
    HANZO_RETURN_IF_ERROR(execute("BEGIN IMMEDIATE"));
    for (const char* sql : {"DELETE FROM map_versions WHERE map_id = ?", "DELETE FROM maps WHERE map_id = ?"}) {
      Statement erase(database_, sql);
      erase.bind(1, map_id);
      if (erase.step() != SQLITE_DONE) {
        Status failed = failure(fmt::format("forget map {}", map_id));
        (void)execute("ROLLBACK");
        return failed;
      }
    }
    return execute("COMMIT");
  }

 private:
  // Caller holds mutex_.
  Result<std::optional<SessionLease>> lease_locked(const std::string& session_id) {
    Statement query(database_, "SELECT owner, owner_url, expires_ns FROM session_leases WHERE session_id = ?");
    query.bind(1, session_id);
    const int code = query.step();
    if (code == SQLITE_DONE) return std::optional<SessionLease>();
    if (code != SQLITE_ROW) return failure(fmt::format("read the lease of session '{}'", session_id));
    return std::optional<SessionLease>(SessionLease{session_id, query.text(0), query.text(1), Timestamp::from_nanoseconds(query.integer(2))});
  }

  Status execute(const std::string& sql) {
    char* message = nullptr;
    if (sqlite3_exec(database_, sql.c_str(), nullptr, nullptr, &message) != SQLITE_OK) {
      Error error(fmt::format("{}: {}", path_, message != nullptr ? message : "unknown SQLite error"));
      sqlite3_free(message);
      return error;
    }
    return ok_status();
  }
  Error failure(const std::string& what) const {
    return Error(fmt::format("{}: cannot {}: {}", path_, what, sqlite3_errmsg(database_)));
  }

  std::mutex mutex_;
  sqlite3* database_;
  std::string path_;
};

}  // namespace

Result<std::unique_ptr<Storage>> open_sqlite_storage(const std::string& path) {
  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  std::error_code ignored;
  if (!parent.empty()) std::filesystem::create_directories(parent, ignored);
  sqlite3* database = nullptr;
  const int flags = SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX;
  if (sqlite3_open_v2(path.c_str(), &database, flags, nullptr) != SQLITE_OK) {
    Error error(fmt::format("{}: cannot open the SQLite database: {}", path,
                            database != nullptr ? sqlite3_errmsg(database) : "out of memory"));
    sqlite3_close_v2(database);
    return error;
  }
  auto storage = std::make_unique<SqliteStorage>(database, path);
  HANZO_RETURN_IF_ERROR(storage->initialize());
  logger()->info("storage: SQLite database {} (WAL, synchronous=FULL)", path);
  return std::unique_ptr<Storage>(std::move(storage));
}

}  // namespace hanzo::fusion::service::detail
