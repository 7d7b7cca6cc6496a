// Storage on PostgreSQL (libpqxx), the same schema as SQLite; trajectory_poses becomes a
// TimescaleDB hypertable (partitioned on timestamp_ns, one-hour chunks) when the extension is
// available. The `time` column (timestamptz) is there for SQL users:
//   SELECT time, x, y FROM trajectory_poses WHERE session_id = '...' AND time > now() - interval '1 hour';
#include <mutex>
#include <optional>

#include <fmt/format.h>
#include <pqxx/pqxx>

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
  created_ns BIGINT NOT NULL,
  ended_ns BIGINT
);
CREATE TABLE IF NOT EXISTS trajectory_poses (
  session_id TEXT NOT NULL,
  timestamp_ns BIGINT NOT NULL,
  time TIMESTAMPTZ NOT NULL,
  x DOUBLE PRECISION NOT NULL, y DOUBLE PRECISION NOT NULL, z DOUBLE PRECISION NOT NULL,
  qw DOUBLE PRECISION NOT NULL, qx DOUBLE PRECISION NOT NULL, qy DOUBLE PRECISION NOT NULL, qz DOUBLE PRECISION NOT NULL,
  vx DOUBLE PRECISION NOT NULL, vy DOUBLE PRECISION NOT NULL, vz DOUBLE PRECISION NOT NULL,
  state TEXT NOT NULL,
  active_sensors TEXT NOT NULL,
  covariance BYTEA,
  PRIMARY KEY (session_id, timestamp_ns)
);
CREATE INDEX IF NOT EXISTS trajectory_poses_by_time ON trajectory_poses (time);
CREATE TABLE IF NOT EXISTS map_versions (
  session_id TEXT NOT NULL,
  map_id TEXT NOT NULL,
  version BIGINT NOT NULL,
  created_ns BIGINT NOT NULL,
  PRIMARY KEY (map_id, version)
);
CREATE INDEX IF NOT EXISTS map_versions_by_session ON map_versions (session_id);
CREATE TABLE IF NOT EXISTS maps (
  map_id TEXT PRIMARY KEY,
  organization TEXT NOT NULL,
  name TEXT NOT NULL,
  session_id TEXT NOT NULL,
  created_ns BIGINT NOT NULL
);
CREATE TABLE IF NOT EXISTS session_leases (
  session_id TEXT PRIMARY KEY,
  owner TEXT NOT NULL,
  owner_url TEXT NOT NULL,
  expires_ns BIGINT NOT NULL
);
)sql";

constexpr const char* kInsertPose =
    "INSERT INTO trajectory_poses (session_id, timestamp_ns, time, x, y, z, qw, qx, qy, qz, vx, vy, vz, state, "
    "active_sensors, covariance) VALUES ($1, $2::bigint, to_timestamp(($2::bigint)::double precision / 1e9), $3, $4, $5, $6, $7, $8, $9, "
    "$10, $11, $12, $13, $14, $15) ON CONFLICT DO NOTHING";

class PostgresqlStorage final : public Storage {
 public:
  PostgresqlStorage(std::unique_ptr<pqxx::connection> connection, std::string uri, std::string where)
      : connection_(std::move(connection)), uri_(std::move(uri)), where_(std::move(where)) {}

  std::string_view backend() const override { return "postgresql"; }

  Status initialize() {
    HANZO_RETURN_IF_ERROR(run("create the schema", [&] {
      pqxx::work work(*connection_);
      work.exec("SELECT pg_advisory_xact_lock(83083)");  // two servers starting on one database
      work.exec(kSchema);
      const pqxx::result version = work.exec("SELECT version FROM hanzo_schema");
      if (version.empty()) {
        work.exec(fmt::format("INSERT INTO hanzo_schema (version) VALUES ({})", kStorageSchemaVersion));
      } else if (version[0][0].as<int>() > kStorageSchemaVersion) {
        schema_error_ = fmt::format("{}: database schema version {} is newer than this program's ({}); upgrade hanzo-fusion",
                                    where_, version[0][0].as<int>(), kStorageSchemaVersion);
        return;
      } else if (version[0][0].as<int>() < kStorageSchemaVersion) {  // the schema above added what is new
        work.exec(fmt::format("UPDATE hanzo_schema SET version = {}", kStorageSchemaVersion));
      }
      work.commit();
      make_hypertable_when_available();
      connection_->prepare("insert_pose", kInsertPose);
    }));
    if (!schema_error_.empty()) return Error(schema_error_);
    return ok_status();
  }

  Status create_session(const SessionRecord& session) override {
    return run(fmt::format("store session '{}'", session.id), [&] {
      pqxx::work work(*connection_);
      const std::optional<int64_t> ended =
          session.ended ? std::optional<int64_t>(session.ended->nanoseconds()) : std::nullopt;
      if (ended) {
        work.exec_params0("INSERT INTO sessions VALUES ($1, $2, $3, $4, $5, $6, $7)", session.id, session.organization,
                          session.name, session.config_yaml, session.calibration_yaml, session.created.nanoseconds(), *ended);
      } else {
        work.exec_params0("INSERT INTO sessions VALUES ($1, $2, $3, $4, $5, $6, NULL)", session.id, session.organization,
                          session.name, session.config_yaml, session.calibration_yaml, session.created.nanoseconds());
      }
      work.commit();
    });
  }

  Status update_session_setup(const std::string& id, const std::string& config_yaml,
                              const std::string& calibration_yaml) override {
    uint64_t changed = 0;
    HANZO_RETURN_IF_ERROR(run(fmt::format("update session '{}'", id), [&] {
      pqxx::work work(*connection_);
      changed = work.exec_params("UPDATE sessions SET config_yaml = $1, calibration_yaml = $2 WHERE id = $3", config_yaml,
                                 calibration_yaml, id).affected_rows();
      work.commit();
    }));
    if (changed != 1) return Error(fmt::format("session '{}' is not stored", id));
    return ok_status();
  }

  Status end_session(const std::string& id, Timestamp ended) override {
    uint64_t changed = 0;
    HANZO_RETURN_IF_ERROR(run(fmt::format("end session '{}'", id), [&] {
      pqxx::work work(*connection_);
      changed = work.exec_params("UPDATE sessions SET ended_ns = $1 WHERE id = $2", ended.nanoseconds(), id).affected_rows();
      work.commit();
    }));
    if (changed != 1) return Error(fmt::format("session '{}' is not stored", id));
    return ok_status();
  }

  Result<std::vector<SessionRecord>> sessions() override {
    std::vector<SessionRecord> records;
    HANZO_RETURN_IF_ERROR(run("list sessions", [&] {
      pqxx::read_transaction work(*connection_);
      for (const pqxx::row& row : work.exec("SELECT id, organization, name, config_yaml, calibration_yaml, created_ns, "
                                            "ended_ns FROM sessions ORDER BY created_ns, id")) {
        SessionRecord& record = records.emplace_back();
        record.id = row[0].as<std::string>();
        record.organization = row[1].as<std::string>();
        record.name = row[2].as<std::string>();
        record.config_yaml = row[3].as<std::string>();
        record.calibration_yaml = row[4].as<std::string>();
        record.created = Timestamp::from_nanoseconds(row[5].as<int64_t>());
        if (!row[6].is_null()) record.ended = Timestamp::from_nanoseconds(row[6].as<int64_t>());
      }
    }));
    return records;
  }

  Status append_poses(const std::vector<StoredPose>& poses) override {
    if (poses.empty()) return ok_status();
    return run("store poses", [&] {
      pqxx::work work(*connection_);
      for (const StoredPose& pose : poses) {
        const msgs::PoseEstimate& estimate = pose.estimate;
        const Eigen::Vector3d& p = estimate.T_world_body.position;
        const Eigen::Quaterniond& q = estimate.T_world_body.orientation;
        const std::string state(msgs::to_string(estimate.status.state));
        const std::string sensors = join_sensors(estimate.status.active_sensors);
        if (estimate.pose_covariance) {
          const std::string bytes = encode_covariance(*estimate.pose_covariance);
          work.exec_prepared0("insert_pose", pose.session_id, estimate.timestamp.nanoseconds(), p.x(), p.y(), p.z(), q.w(),
                              q.x(), q.y(), q.z(), estimate.velocity.x(), estimate.velocity.y(), estimate.velocity.z(),
                              state, sensors, pqxx::binarystring(bytes.data(), bytes.size()));
        } else {
          work.exec_prepared0("insert_pose", pose.session_id, estimate.timestamp.nanoseconds(), p.x(), p.y(), p.z(), q.w(),
                              q.x(), q.y(), q.z(), estimate.velocity.x(), estimate.velocity.y(), estimate.velocity.z(),
                              state, sensors, nullptr);
        }
      }
      work.commit();
    });
  }

  Result<std::vector<msgs::PoseEstimate>> poses(const std::string& session_id, Timestamp after, std::size_t limit) override {
    std::vector<msgs::PoseEstimate> estimates;
    HANZO_RETURN_IF_ERROR(run(fmt::format("read the trajectory of session '{}'", session_id), [&] {
      pqxx::read_transaction work(*connection_);
      const pqxx::result rows = work.exec_params(
          "SELECT timestamp_ns, x, y, z, qw, qx, qy, qz, vx, vy, vz, state, active_sensors, covariance "
          "FROM trajectory_poses WHERE session_id = $1 AND timestamp_ns > $2 ORDER BY timestamp_ns LIMIT $3",
          session_id, after.nanoseconds(), static_cast<int64_t>(limit));
      for (const pqxx::row& row : rows) {
        msgs::PoseEstimate& estimate = estimates.emplace_back();
        estimate.timestamp = Timestamp::from_nanoseconds(row[0].as<int64_t>());
        estimate.frame_id = msgs::kWorldFrame;
        estimate.child_frame_id = msgs::kBodyFrame;
        estimate.T_world_body.position = {row[1].as<double>(), row[2].as<double>(), row[3].as<double>()};
        estimate.T_world_body.orientation =
            Eigen::Quaterniond(row[4].as<double>(), row[5].as<double>(), row[6].as<double>(), row[7].as<double>());
        estimate.velocity = {row[8].as<double>(), row[9].as<double>(), row[10].as<double>()};
        estimate.status.state = tracking_state_from_name(row[11].as<std::string>());
        estimate.status.active_sensors = split_sensors(row[12].as<std::string>());
        estimate.status.active_modalities = static_cast<uint32_t>(estimate.status.active_sensors.size());
        if (!row[13].is_null()) {
          const pqxx::binarystring bytes(row[13]);
          estimate.pose_covariance = decode_covariance(std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
        }
      }
    }));
    return estimates;
  }

  Result<TrajectoryExtent> trajectory_extent(const std::string& session_id) override {
    TrajectoryExtent extent;
    HANZO_RETURN_IF_ERROR(run(fmt::format("count the poses of session '{}'", session_id), [&] {
      pqxx::read_transaction work(*connection_);
      const pqxx::row row = work.exec_params1(
          "SELECT COUNT(*), MIN(timestamp_ns), MAX(timestamp_ns) FROM trajectory_poses WHERE session_id = $1", session_id);
      extent.count = row[0].as<uint64_t>();
      if (!row[1].is_null()) extent.first = Timestamp::from_nanoseconds(row[1].as<int64_t>());
      if (!row[2].is_null()) extent.last = Timestamp::from_nanoseconds(row[2].as<int64_t>());
    }));
    return extent;
  }

  // The upsert takes the row lock: of two replicas claiming one expired lease, the second
  // waits for the first and then sees a lease that has not expired.
  Result<SessionLease> claim_session(const std::string& session_id, const std::string& owner, const std::string& owner_url,
                                     Timestamp now, Timestamp expires) override {
    SessionLease lease;
    HANZO_RETURN_IF_ERROR(run(fmt::format("claim session '{}'", session_id), [&] {
      pqxx::work work(*connection_);
      work.exec_params0(
          "INSERT INTO session_leases (session_id, owner, owner_url, expires_ns) VALUES ($1, $2, $3, $4) "
          "ON CONFLICT (session_id) DO UPDATE SET owner = EXCLUDED.owner, owner_url = EXCLUDED.owner_url, "
          "expires_ns = EXCLUDED.expires_ns WHERE session_leases.expires_ns < $5 OR session_leases.owner = EXCLUDED.owner",
          session_id, owner, owner_url, expires.nanoseconds(), now.nanoseconds());
      const pqxx::row row = work.exec_params1("SELECT owner, owner_url, expires_ns FROM session_leases WHERE session_id = $1", session_id);
      lease = {session_id, row[0].as<std::string>(), row[1].as<std::string>(), Timestamp::from_nanoseconds(row[2].as<int64_t>())};
      work.commit();
    }));
    return lease;
  }

  Result<std::vector<std::string>> renew_leases(const std::string& owner, Timestamp expires) override {
    std::vector<std::string> held;
    HANZO_RETURN_IF_ERROR(run("renew session leases", [&] {
      pqxx::work work(*connection_);
      for (const pqxx::row& row : work.exec_params("UPDATE session_leases SET expires_ns = $1 WHERE owner = $2 RETURNING session_id",
                                                   expires.nanoseconds(), owner)) {
        held.push_back(row[0].as<std::string>());
      }
      work.commit();
    }));
    return held;
  }

  Result<std::optional<SessionLease>> session_lease(const std::string& session_id) override {
    std::optional<SessionLease> lease;
    HANZO_RETURN_IF_ERROR(run(fmt::format("read the lease of session '{}'", session_id), [&] {
      pqxx::read_transaction work(*connection_);
      const pqxx::result rows = work.exec_params("SELECT owner, owner_url, expires_ns FROM session_leases WHERE session_id = $1", session_id);
      if (!rows.empty()) {
        lease = SessionLease{session_id, rows[0][0].as<std::string>(), rows[0][1].as<std::string>(),
                             Timestamp::from_nanoseconds(rows[0][2].as<int64_t>())};
      }
    }));
    return lease;
  }

  Result<bool> transfer_session(const std::string& session_id, const std::string& owner, const std::string& new_owner,
                                const std::string& new_owner_url, Timestamp expires) override {
    uint64_t changed = 0;
    HANZO_RETURN_IF_ERROR(run(fmt::format("hand session '{}' over", session_id), [&] {
      pqxx::work work(*connection_);
      changed = work.exec_params("UPDATE session_leases SET owner = $1, owner_url = $2, expires_ns = $3 WHERE session_id = $4 AND owner = $5",
                                 new_owner, new_owner_url, expires.nanoseconds(), session_id, owner).affected_rows();
      work.commit();
    }));
    return changed == 1;
  }

  Status release_session(const std::string& session_id, const std::string& owner) override {
    return run(fmt::format("release session '{}'", session_id), [&] {
      pqxx::work work(*connection_);
      work.exec_params0("DELETE FROM session_leases WHERE session_id = $1 AND owner = $2", session_id, owner);
      work.commit();
    });
  }

  Status create_map(const MapRecord& map) override {
    return run(fmt::format("store map '{}'", map.map_id), [&] {
      pqxx::work work(*connection_);
      work.exec_params0("INSERT INTO maps (map_id, organization, name, session_id, created_ns) VALUES ($1, $2, $3, $4, $5)",
                        map.map_id, map.organization, map.name, map.session_id, map.created.nanoseconds());
      work.commit();
    });
  }

  Result<std::vector<MapRecord>> maps() override {
    std::vector<MapRecord> records;
    HANZO_RETURN_IF_ERROR(run("list maps", [&] {
      pqxx::read_transaction work(*connection_);
      for (const pqxx::row& row : work.exec("SELECT map_id, organization, name, session_id, created_ns FROM maps ORDER BY created_ns, map_id")) {
        records.push_back({row[0].as<std::string>(), row[1].as<std::string>(), row[2].as<std::string>(), row[3].as<std::string>(),
                           Timestamp::from_nanoseconds(row[4].as<int64_t>())});
      }
    }));
    return records;
  }

  Status record_map_version(const MapVersionRecord& record) override {
    return run(fmt::format("record map {} version {}", record.map_id, record.version), [&] {
      pqxx::work work(*connection_);
      work.exec_params0("INSERT INTO map_versions (session_id, map_id, version, created_ns) VALUES ($1, $2, $3, $4)",
                        record.session_id, record.map_id, static_cast<int64_t>(record.version), record.created.nanoseconds());
      work.commit();
    });
  }

  Result<std::vector<MapVersionRecord>> map_versions(const std::string& session_id) override {
    std::vector<MapVersionRecord> records;
    HANZO_RETURN_IF_ERROR(run("list map versions", [&] {
      pqxx::read_transaction work(*connection_);
      for (const pqxx::row& row : work.exec_params("SELECT map_id, version, created_ns FROM map_versions WHERE session_id = $1 "
                                                   "ORDER BY created_ns, version", session_id)) {
        records.push_back({session_id, row[0].as<std::string>(), row[1].as<uint64_t>(),
                           Timestamp::from_nanoseconds(row[2].as<int64_t>())});
      }
    }));
    return records;
  }

  Status delete_map_version(const std::string& map_id, uint64_t version) override {
    return run(fmt::format("forget map {} version {}", map_id, version), [&] {
      pqxx::work work(*connection_);
      work.exec_params0("DELETE FROM map_versions WHERE map_id = $1 AND version = $2", map_id, static_cast<int64_t>(version));
      work.commit();
    });
  }

  Status delete_map(const std::string& map_id) override {
    return run(fmt::format("forget map {}", map_id), [&] {
      pqxx::work work(*connection_);
      work.exec_params0("DELETE FROM map_versions WHERE map_id = $1", map_id);
      work.exec_params0("DELETE FROM maps WHERE map_id = $1", map_id);
      work.commit();
    });
  }

 private:
  // Runs `body` under the connection's lock; a database exception becomes an error naming
  // `what` (and the connection is re-opened on the next call when it was lost).
  template <typename Body>
  Status run(const std::string& what, Body&& body) {
    std::lock_guard lock(mutex_);
    try {
      if (!connection_->is_open()) {  // the server went away: connect afresh
        connection_ = std::make_unique<pqxx::connection>(uri_);
        connection_->prepare("insert_pose", kInsertPose);
      }
      body();
      return ok_status();
    } catch (const std::exception& exception) {
      std::string reason = exception.what();
      while (!reason.empty() && (reason.back() == '\n' || reason.back() == ' ')) reason.pop_back();
      return Error(fmt::format("{}: cannot {}: {}", where_, what, reason));
    }
  }

  void make_hypertable_when_available() {
    try {
      pqxx::work work(*connection_);
      if (work.exec("SELECT 1 FROM pg_available_extensions WHERE name = 'timescaledb'").empty()) {
        logger()->info("storage: TimescaleDB is not available; trajectory_poses is a plain table indexed by time");
        return;
      }
      work.exec("CREATE EXTENSION IF NOT EXISTS timescaledb");
      work.exec("SELECT create_hypertable('trajectory_poses', 'timestamp_ns', chunk_time_interval => 3600000000000, "
                "if_not_exists => TRUE, migrate_data => TRUE)");
      work.commit();
      logger()->info("storage: trajectory_poses is a TimescaleDB hypertable");
    } catch (const std::exception& exception) {
      logger()->warn("storage: TimescaleDB is available but the hypertable failed ({}); keeping a plain table", exception.what());
    }
  }

  std::mutex mutex_;
  std::unique_ptr<pqxx::connection> connection_;
  std::string uri_;
  std::string where_;
  std::string schema_error_;
};

}  // namespace

Result<std::unique_ptr<Storage>> open_postgresql_storage(const std::string& uri) {
  // The URI may carry a password: errors name the host part only.
  const std::size_t at = uri.rfind('@');
  const std::string where = "PostgreSQL " + (at == std::string::npos ? uri : uri.substr(0, uri.find("://") + 3) + "..." + uri.substr(at));
  std::unique_ptr<pqxx::connection> connection;
  try {
    connection = std::make_unique<pqxx::connection>(uri);
  } catch (const std::exception& exception) {
    std::string reason = exception.what();
    while (!reason.empty() && (reason.back() == '\n' || reason.back() == ' ')) reason.pop_back();
    return Error(fmt::format("{}: cannot connect: {}", where, reason));
  }
  auto storage = std::make_unique<PostgresqlStorage>(std::move(connection), uri, where);
  HANZO_RETURN_IF_ERROR(storage->initialize());
  logger()->info("storage: {}", where);
  return std::unique_ptr<Storage>(std::move(storage));
}

}  // namespace hanzo::fusion::service::detail
