// Both storage backends against the same expectations: SQLite in a scratch folder, PostgreSQL
// on the server the ctest fixture started (a fresh database per test).
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <random>
#include <thread>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <pqxx/pqxx>
#include <sqlite3.h>

#include "hanzo/fusion/service/storage.hpp"
#include "service_fixtures.hpp"

namespace hanzo::fusion::service {
namespace {

using ::testing::HasSubstr;

msgs::PoseEstimate make_pose(int64_t ns, double x, bool with_covariance) {
  msgs::PoseEstimate pose;
  pose.timestamp = Timestamp::from_nanoseconds(ns);
  pose.T_world_body.position = {x, -2.0 * x + 0.1, 1.0 / 3.0};
  pose.T_world_body.orientation = Eigen::Quaterniond(Eigen::AngleAxisd(0.001 * x, Eigen::Vector3d(0.3, 0.4, 0.5).normalized()));
  pose.velocity = {0.5, std::nextafter(1.0, 2.0), -1e-300};
  pose.status.state = msgs::TrackingState::kDegraded;
  pose.status.active_sensors = {"imu", "gnss"};
  pose.status.active_modalities = 2;
  if (with_covariance) {
    msgs::Matrix6d covariance = msgs::Matrix6d::Identity() * 0.01;
    covariance(0, 5) = covariance(5, 0) = 1e-7 * x;
    pose.pose_covariance = covariance;
  }
  return pose;
}

void expect_same_pose(const msgs::PoseEstimate& stored, const msgs::PoseEstimate& original) {
  EXPECT_EQ(stored.timestamp, original.timestamp);
  EXPECT_EQ(stored.T_world_body.position, original.T_world_body.position);  // bit-exact doubles
  EXPECT_EQ(stored.T_world_body.orientation.coeffs(), original.T_world_body.orientation.coeffs());
  EXPECT_EQ(stored.velocity, original.velocity);
  EXPECT_EQ(stored.status.state, original.status.state);
  EXPECT_EQ(stored.status.active_sensors, original.status.active_sensors);
  ASSERT_EQ(stored.pose_covariance.has_value(), original.pose_covariance.has_value());
  if (original.pose_covariance) {
    EXPECT_EQ(*stored.pose_covariance, *original.pose_covariance);
  }
}

// A fresh database on the test PostgreSQL server.
std::string fresh_postgres_database() {
  const std::string server = testing::postgres_test_url();
  EXPECT_FALSE(server.empty()) << "the PostgreSQL test server is not running (scripts/test-postgres.sh)";
  static std::mt19937_64 random(std::random_device{}());
  const std::string name = fmt::format("hanzo_test_{:x}", random());
  pqxx::connection connection(server);
  pqxx::nontransaction work(connection);
  work.exec("CREATE DATABASE " + name);
  return server.substr(0, server.rfind('/') + 1) + name;
}

class StorageTest : public ::testing::TestWithParam<std::string> {
 protected:
  std::string url() {
    if (url_.empty()) {
      url_ = GetParam() == "sqlite" ? "sqlite://" + (testing::scratch_dir() / "fusion.db").string() : fresh_postgres_database();
    }
    return url_;
  }
  std::unique_ptr<Storage> open() {
    auto storage = open_storage(url());
    EXPECT_TRUE(storage.ok()) << storage.error().message;
    return storage.ok() ? std::move(storage).value() : nullptr;
  }

 private:
  std::string url_;
};

TEST_P(StorageTest, SessionsAndTrajectoriesRoundTripExactly) {
  auto storage = open();
  ASSERT_TRUE(storage);
  EXPECT_EQ(storage->backend(), GetParam());
  SessionRecord session{"s1", "acme", "warehouse run", "fusion:\n  sensors: {}\n", "calibration: {}\n",
                        Timestamp::from_nanoseconds(1'700'000'000'000'000'000), std::nullopt};
  ASSERT_TRUE(storage->create_session(session).ok());
  EXPECT_FALSE(storage->create_session(session).ok());  // id taken

  std::vector<StoredPose> poses;
  for (int i = 0; i < 250; ++i) poses.push_back({"s1", make_pose(1'000'000'000 + i * 5'000'000LL, i * 0.1, i % 3 != 0)});
  const Status appended = storage->append_poses(poses);
  ASSERT_TRUE(appended.ok()) << appended.error().message;
  // Re-sent poses (a client retrying) are kept once.
  ASSERT_TRUE(storage->append_poses({poses[10], poses[11]}).ok());

  const auto extent = storage->trajectory_extent("s1");
  ASSERT_TRUE(extent.ok()) << extent.error().message;
  EXPECT_EQ(extent->count, 250u);
  EXPECT_EQ(extent->first, poses.front().estimate.timestamp);
  EXPECT_EQ(extent->last, poses.back().estimate.timestamp);
  EXPECT_EQ(storage->trajectory_extent("other")->count, 0u);

  // Paging: 100 at a time after the last timestamp seen.
  std::vector<msgs::PoseEstimate> read;
  Timestamp after = Timestamp::from_nanoseconds(std::numeric_limits<int64_t>::min());
  while (true) {
    auto page = storage->poses("s1", after, 100);
    ASSERT_TRUE(page.ok()) << page.error().message;
    if (page->empty()) break;
    read.insert(read.end(), page->begin(), page->end());
    after = page->back().timestamp;
  }
  ASSERT_EQ(read.size(), poses.size());
  for (std::size_t i = 0; i < read.size(); ++i) expect_same_pose(read[i], poses[i].estimate);

  ASSERT_TRUE(storage->update_session_setup("s1", "fusion:\n  sensors: {imu: {rate: 100}}\n", "calibration: {}\n").ok());
  ASSERT_TRUE(storage->end_session("s1", Timestamp::from_nanoseconds(1'700'000'100'000'000'000)).ok());
  EXPECT_FALSE(storage->end_session("missing", Timestamp::from_nanoseconds(1)).ok());
  ASSERT_TRUE(storage->record_map_version({"s1", "map-a", 1, Timestamp::from_nanoseconds(5)}).ok());
  ASSERT_TRUE(storage->record_map_version({"s1", "map-a", 2, Timestamp::from_nanoseconds(6)}).ok());
  EXPECT_FALSE(storage->record_map_version({"s1", "map-a", 2, Timestamp::from_nanoseconds(7)}).ok());
  ASSERT_TRUE(storage->create_map({"map-a", "acme", "warehouse", "s1", Timestamp::from_nanoseconds(5)}).ok());
  ASSERT_TRUE(storage->create_map({"plan-b", "other", "uploaded", "", Timestamp::from_nanoseconds(9)}).ok());
  EXPECT_FALSE(storage->create_map({"map-a", "other", "taken", "", Timestamp::from_nanoseconds(10)}).ok());  // id taken

  // Everything is there after reopening.
  storage.reset();
  storage = open();
  ASSERT_TRUE(storage);
  const auto sessions = storage->sessions();
  ASSERT_TRUE(sessions.ok());
  ASSERT_EQ(sessions->size(), 1u);
  EXPECT_EQ(sessions->front().name, "warehouse run");
  EXPECT_EQ(sessions->front().organization, "acme");
  EXPECT_EQ(sessions->front().config_yaml, "fusion:\n  sensors: {imu: {rate: 100}}\n");
  EXPECT_EQ(sessions->front().created, session.created);
  EXPECT_EQ(sessions->front().ended, Timestamp::from_nanoseconds(1'700'000'100'000'000'000));
  const auto maps = storage->map_versions("s1");
  ASSERT_TRUE(maps.ok());
  ASSERT_EQ(maps->size(), 2u);
  EXPECT_EQ(maps->back().version, 2u);
  const auto map_records = storage->maps();
  ASSERT_TRUE(map_records.ok()) << map_records.error().message;
  ASSERT_EQ(map_records->size(), 2u);
  EXPECT_EQ(map_records->front().map_id, "map-a");
  EXPECT_EQ(map_records->front().organization, "acme");
  EXPECT_EQ(map_records->front().name, "warehouse");
  EXPECT_EQ(map_records->front().session_id, "s1");
  EXPECT_EQ(map_records->back().session_id, "");
  EXPECT_EQ(map_records->back().created, Timestamp::from_nanoseconds(9));
  EXPECT_EQ(storage->trajectory_extent("s1")->count, 250u);
}

// A database of schema version 1 (no maps table) is upgraded in place, keeping its sessions.
TEST_P(StorageTest, UpgradesAVersionOneDatabase) {
  {
    auto storage = open();
    ASSERT_TRUE(storage);
    ASSERT_TRUE(storage->create_session({"s1", "acme", "old", "fusion: {}\n", "", Timestamp::from_nanoseconds(1), std::nullopt}).ok());
  }
  const char* downgrade = "DROP TABLE maps; UPDATE hanzo_schema SET version = 1";
  if (GetParam() == "sqlite") {
    const std::string path = url().substr(std::string("sqlite://").size());
    sqlite3* database = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &database), SQLITE_OK);
    ASSERT_EQ(sqlite3_exec(database, downgrade, nullptr, nullptr, nullptr), SQLITE_OK);
    sqlite3_close(database);
  } else {
    pqxx::connection connection(url());
    pqxx::work work(connection);
    work.exec(downgrade);
    work.commit();
  }
  auto storage = open();
  ASSERT_TRUE(storage);
  EXPECT_EQ(storage->sessions()->size(), 1u);
  ASSERT_TRUE(storage->create_map({"m", "acme", "new", "", Timestamp::from_nanoseconds(2)}).ok());
  EXPECT_EQ(storage->maps()->size(), 1u);
}

TEST_P(StorageTest, RefusesADatabaseOfANewerSchema) {
  ASSERT_TRUE(open());
  // Bump the stored version as a newer hanzo-fusion would.
  if (GetParam() == "sqlite") {
    const std::string path = url().substr(std::string("sqlite://").size());
    sqlite3* database = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &database), SQLITE_OK);
    ASSERT_EQ(sqlite3_exec(database, "UPDATE hanzo_schema SET version = 99", nullptr, nullptr, nullptr), SQLITE_OK);
    sqlite3_close(database);
  } else {
    pqxx::connection connection(url());
    pqxx::work work(connection);
    work.exec("UPDATE hanzo_schema SET version = 99");
    work.commit();
  }
  auto storage = open_storage(url());
  ASSERT_FALSE(storage.ok());
  EXPECT_THAT(storage.error().message, HasSubstr("schema version 99 is newer"));
}

// Session leases: one holder at a time, renewed by its holder, claimable once expired, and of
// two replicas racing for an expired lease (two connections) exactly one wins.
TEST_P(StorageTest, SessionLeasesHaveOneHolderAndExpire) {
  auto replica_a = open();
  auto replica_b = open();
  ASSERT_TRUE(replica_a && replica_b);
  const auto at = [](int64_t seconds) { return Timestamp::from_nanoseconds(1'700'000'000'000'000'000 + seconds * 1'000'000'000); };
  EXPECT_FALSE(replica_a->session_lease("s1")->has_value());

  auto claimed = replica_a->claim_session("s1", "a", "http://a:8083", at(0), at(10));
  ASSERT_TRUE(claimed.ok()) << claimed.error().message;
  EXPECT_EQ(claimed->owner, "a");
  // B cannot take a lease that has not expired; it learns who holds it and where.
  auto refused = replica_b->claim_session("s1", "b", "http://b:8083", at(5), at(15));
  ASSERT_TRUE(refused.ok()) << refused.error().message;
  EXPECT_EQ(refused->owner, "a");
  EXPECT_EQ(refused->owner_url, "http://a:8083");
  EXPECT_EQ(refused->expires, at(10));

  // A renews what it holds (B holds nothing).
  auto renewed = replica_a->renew_leases("a", at(20));
  ASSERT_TRUE(renewed.ok()) << renewed.error().message;
  EXPECT_EQ(*renewed, std::vector<std::string>{"s1"});
  EXPECT_TRUE(replica_b->renew_leases("b", at(20))->empty());
  EXPECT_EQ(replica_b->claim_session("s1", "b", "http://b:8083", at(15), at(25))->owner, "a");

  // Expired: B takes it; A's renewal no longer covers it.
  auto taken = replica_b->claim_session("s1", "b", "http://b:8083", at(21), at(31));
  ASSERT_TRUE(taken.ok());
  EXPECT_EQ(taken->owner, "b");
  EXPECT_TRUE(replica_a->renew_leases("a", at(40))->empty());
  EXPECT_EQ(replica_a->session_lease("s1")->value().owner, "b");

  // Released by its holder only; then anyone may claim it at once.
  ASSERT_TRUE(replica_a->release_session("s1", "a").ok());
  EXPECT_TRUE(replica_a->session_lease("s1")->has_value());
  ASSERT_TRUE(replica_b->release_session("s1", "b").ok());
  EXPECT_FALSE(replica_a->session_lease("s1")->has_value());

  // Handed over by its holder only, in one step.
  ASSERT_TRUE(replica_a->claim_session("s3", "a", "http://a:8083", at(0), at(10)).ok());
  EXPECT_FALSE(replica_b->transfer_session("s3", "b", "c", "http://c:8083", at(12)).value());
  ASSERT_TRUE(replica_a->transfer_session("s3", "a", "c", "http://c:8083", at(12)).value());
  const SessionLease handed = replica_b->session_lease("s3")->value();
  EXPECT_EQ(handed.owner, "c");
  EXPECT_EQ(handed.owner_url, "http://c:8083");
  EXPECT_EQ(handed.expires, at(12));

  // A race for an expired lease from two threads: one winner, both see the same holder.
  ASSERT_TRUE(replica_a->claim_session("s2", "a", "http://a:8083", at(0), at(1)).ok());
  for (int round = 0; round < 20; ++round) {
    const Timestamp now = at(100 + 20 * round), until = at(110 + 20 * round);
    SessionLease seen_by_b, seen_by_c;
    auto replica_c = open();
    std::thread racer_b([&] { seen_by_b = replica_b->claim_session("s2", "b", "http://b", now, until).value(); });
    std::thread racer_c([&] { seen_by_c = replica_c->claim_session("s2", "c", "http://c", now, until).value(); });
    racer_b.join();
    racer_c.join();
    EXPECT_EQ(seen_by_b.owner, seen_by_c.owner) << "round " << round;
  }
}

// Every append the storage acknowledged survives kill -9 of the process that made it.
TEST_P(StorageTest, AcknowledgedPosesSurviveKillNine) {
  ASSERT_TRUE(open());  // schema created before the child starts
  int pipe_fds[2];
  ASSERT_EQ(pipe(pipe_fds), 0);
  const std::string database = url();
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    close(pipe_fds[0]);
    auto storage = open_storage(database);
    if (!storage) _exit(3);
    for (int batch = 0;; ++batch) {
      std::vector<StoredPose> poses;
      for (int i = 0; i < 50; ++i) poses.push_back({"crash", make_pose((batch * 50 + i + 1) * 1'000'000LL, batch + i * 0.01, true)});
      if (!storage.value()->append_poses(poses)) _exit(4);
      const int acknowledged = (batch + 1) * 50;
      if (write(pipe_fds[1], &acknowledged, sizeof(acknowledged)) != sizeof(acknowledged)) _exit(5);
    }
  }
  close(pipe_fds[1]);
  int acknowledged = 0;
  while (acknowledged < 3000) {
    ASSERT_EQ(read(pipe_fds[0], &acknowledged, sizeof(acknowledged)), static_cast<ssize_t>(sizeof(acknowledged)));
  }
  kill(child, SIGKILL);
  int status = 0;
  waitpid(child, &status, 0);
  // Drain what the child acknowledged before it died.
  int more = 0;
  while (read(pipe_fds[0], &more, sizeof(more)) == static_cast<ssize_t>(sizeof(more))) acknowledged = more;
  close(pipe_fds[0]);
  EXPECT_TRUE(WIFSIGNALED(status));

  auto storage = open();
  ASSERT_TRUE(storage);
  const auto extent = storage->trajectory_extent("crash");
  ASSERT_TRUE(extent.ok()) << extent.error().message;
  EXPECT_GE(extent->count, static_cast<uint64_t>(acknowledged));
  EXPECT_EQ(extent->count % 50, 0u) << "a batch is all or nothing";
  const auto poses = storage->poses("crash", Timestamp::from_nanoseconds(0), static_cast<std::size_t>(acknowledged));
  ASSERT_TRUE(poses.ok());
  ASSERT_EQ(poses->size(), static_cast<std::size_t>(acknowledged));
  for (int i = 0; i < acknowledged; ++i) EXPECT_EQ((*poses)[i].timestamp.nanoseconds(), (i + 1) * 1'000'000LL);
}

INSTANTIATE_TEST_SUITE_P(Backends, StorageTest, ::testing::Values("sqlite", "postgresql"),
                         [](const auto& backend) { return backend.param; });

TEST(Storage, OpenFailsWithAReason) {
  EXPECT_THAT(open_storage("").error().message, HasSubstr("empty"));
  EXPECT_THAT(open_storage("mysql://x").error().message, HasSubstr("unknown scheme"));
  EXPECT_THAT(open_storage("sqlite:///proc/forbidden/fusion.db").error().message, HasSubstr("/proc/forbidden/fusion.db"));
  const auto refused = open_storage("postgresql://nobody:secret@127.0.0.1:1/none");
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused.error().message, HasSubstr("cannot connect"));
  EXPECT_THAT(refused.error().message, ::testing::Not(HasSubstr("secret")));  // passwords stay out of errors
}

}  // namespace
}  // namespace hanzo::fusion::service
