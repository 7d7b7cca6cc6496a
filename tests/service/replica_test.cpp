// Replicas on one database and one map store (docs/server.md "Replicas"): a session is served
// by the replica holding its lease; another replica names that one, reads the session's stored
// trajectory, and takes the session over once its replica was killed (kill -9) and the lease ran
// out: its filter resumes from the newest stored pose and the trajectory continues in its frame.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/service/session_manager.hpp"
#include "service_fixtures.hpp"

namespace hanzo::fusion::service {
namespace {

const Principal kRobot{"robot", "acme",
                       static_cast<uint32_t>(Permission::kSessionWrite) | static_cast<uint32_t>(Permission::kSessionRead) |
                           static_cast<uint32_t>(Permission::kMapRead)};

std::unique_ptr<SessionManager> open_replica(const std::filesystem::path& dir, const std::string& id) {
  SessionManagerConfig config;
  config.storage_flush_interval = std::chrono::milliseconds(5);
  config.map_directory = (dir / "maps").string();
  config.map_save_interval = std::chrono::seconds(0);  // saved when asked
  if (!id.empty()) config.replica = {id, "http://" + id + ".invalid:8083", std::chrono::milliseconds(1000), nullptr};
  auto storage = open_storage("sqlite://" + (dir / "fusion.db").string());
  EXPECT_TRUE(storage.ok()) << storage.error().message;
  if (!storage.ok()) return nullptr;
  auto manager = SessionManager::create(config, std::move(storage).value(), std::make_shared<MetricsRegistry>());
  EXPECT_TRUE(manager.ok()) << manager.error().message;
  return manager.ok() ? std::move(manager).value() : nullptr;
}

/// How far `poses` (from `from` on) lie from the reference poses at the same times: mean and
/// largest position gap (m) and the number of poses compared.
struct Gaps {
  double mean = 0.0, largest = 0.0;
  std::size_t compared = 0;
};

Gaps gaps_from(const std::vector<msgs::PoseEstimate>& reference, const std::vector<msgs::PoseEstimate>& poses, Timestamp from) {
  Gaps gaps;
  double sum = 0.0;
  for (const msgs::PoseEstimate& pose : poses) {
    if (pose.timestamp < from) continue;
    const auto same_time = std::lower_bound(reference.begin(), reference.end(), pose.timestamp,
                                            [](const msgs::PoseEstimate& other, Timestamp t) { return other.timestamp < t; });
    if (same_time == reference.end() || same_time->timestamp != pose.timestamp) continue;
    const double gap = (same_time->T_world_body.position - pose.T_world_body.position).norm();
    gaps.largest = std::max(gaps.largest, gap);
    sum += gap;
    ++gaps.compared;
  }
  if (gaps.compared > 0) gaps.mean = sum / static_cast<double>(gaps.compared);
  return gaps;
}

// Kills the forked replica when the test ends early.
struct KilledAtExit {
  pid_t pid = -1;
  ~KilledAtExit() {
    if (pid > 0) {
      kill(pid, SIGKILL);
      waitpid(pid, nullptr, 0);
    }
  }
};

std::vector<msgs::PoseEstimate> stored_trajectory(SessionManager& manager, const std::string& id) {
  auto page = manager.trajectory(kRobot, id, Timestamp::from_nanoseconds(std::numeric_limits<int64_t>::min()), 100000);
  EXPECT_TRUE(page.ok()) << page.error().message;
  return page.ok() ? page->poses : std::vector<msgs::PoseEstimate>{};
}

TEST(Replicas, ASessionOfAKilledReplicaIsTakenOverAndContinuesInItsFrame) {
  const testing::Recording recording = testing::lidar_recording("examples/scenarios/warehouse_robot.yaml", 20.0);
  const Timestamp start = msgs::timestamp_of(recording.messages.front().message);
  // The replica dies 10 s in (driving); the rest of the drive reaches the replica that takes over.
  const auto takeover = std::find_if(recording.messages.begin(), recording.messages.end(), [&](const testing::TimedMessage& m) {
    return (msgs::timestamp_of(m.message) - start).seconds() >= 10.0;
  });
  const std::size_t half = static_cast<std::size_t>(takeover - recording.messages.begin());

  const auto dir = testing::scratch_dir();
  int pipe_fds[2];
  ASSERT_EQ(pipe(pipe_fds), 0);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {  // replica a: serves the session's first 7 s, saves its map, then is killed
    close(pipe_fds[0]);
    auto replica_a = open_replica(dir, "a");
    if (!replica_a) _exit(3);
    auto created = replica_a->create_session(kRobot, {"drive", recording.config_yaml, recording.calibration_yaml});
    if (!created.ok()) _exit(4);
    for (std::size_t i = 0; i < half; ++i) (void)replica_a->push(kRobot, created->id, recording.messages[i].sensor, recording.messages[i].message);
    if (!replica_a->save_session_maps().ok() || !replica_a->flush_storage().ok()) _exit(5);
    const std::string& id = created->id;
    if (write(pipe_fds[1], id.data(), id.size()) != static_cast<ssize_t>(id.size())) _exit(6);
    while (true) pause();
  }
  KilledAtExit guard{child};
  close(pipe_fds[1]);
  // Meanwhile (forked first: no threads in the parent yet) the drive without a failure on a
  // single server: the reference.
  // Twice: the two uninterrupted runs' difference is the floor of the comparison (the session
  // registers sweeps in real time, so runs differ where the machine's load made one skip).
  std::vector<std::vector<msgs::PoseEstimate>> uninterrupted_runs;
  for (const char* suffix : {"-single", "-single-again"}) {
    auto single = open_replica(testing::scratch_dir(suffix), "");
    ASSERT_TRUE(single);
    const std::string id = single->create_session(kRobot, {"single", recording.config_yaml, recording.calibration_yaml}).value().id;
    for (const testing::TimedMessage& message : recording.messages) (void)single->push(kRobot, id, message.sensor, message.message);
    ASSERT_TRUE(single->flush_storage().ok());
    uninterrupted_runs.push_back(stored_trajectory(*single, id));
  }
  const std::vector<msgs::PoseEstimate>& uninterrupted = uninterrupted_runs.front();

  std::string id(32, '\0');
  ASSERT_EQ(read(pipe_fds[0], id.data(), id.size()), 32) << "replica a did not serve the session";
  close(pipe_fds[0]);

  auto replica_b = open_replica(dir, "b");
  ASSERT_TRUE(replica_b);
  // While a holds the lease, b names a and reads what is stored.
  const ApiStatus refused = replica_b->push(kRobot, id, recording.messages[half].sensor, recording.messages[half].message);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kUnavailable);
  EXPECT_EQ(refused.error().served_by, "http://a.invalid:8083");
  const auto listed = replica_b->list_sessions(kRobot);
  ASSERT_TRUE(listed.ok());
  ASSERT_EQ(listed->size(), 1U);
  EXPECT_EQ(listed->front().replica, "a");
  const std::vector<msgs::PoseEstimate> before = stored_trajectory(*replica_b, id);
  ASSERT_GT(before.size(), 1000U);
  const msgs::FusionMap saved_map = replica_b->stored_map(kRobot, id).value();
  ASSERT_TRUE(saved_map.lidar_keyframes);

  kill(child, SIGKILL);
  waitpid(child, nullptr, 0);
  guard.pid = -1;
  // The 1 s lease runs out, then one more period: b's lease keeper (its thread, or this call)
  // takes the session over; the session list says who serves it without asking for it.
  const auto served_by_b = [&] {
    const auto sessions = replica_b->list_sessions(kRobot);
    return sessions.ok() && sessions->size() == 1 && sessions->front().replica == "b";
  };
  for (int pass = 0; pass < 200 && !served_by_b(); ++pass) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    auto kept = replica_b->keep_leases();
    ASSERT_TRUE(kept.ok()) << kept.error().message;
  }
  ASSERT_TRUE(served_by_b()) << "replica b did not take the session over";

  for (std::size_t i = half; i < recording.messages.size(); ++i) {
    const ApiStatus pushed = replica_b->push(kRobot, id, recording.messages[i].sensor, recording.messages[i].message);
    ASSERT_TRUE(pushed.ok() || pushed.error().code == ErrorCode::kRejected) << pushed.error().message;
  }
  ASSERT_TRUE(replica_b->flush_storage().ok());
  const std::vector<msgs::PoseEstimate> after = stored_trajectory(*replica_b, id);
  ASSERT_GT(after.size(), before.size() + 500) << "the session continued on replica b";
  // Every pose stored before the failure is still there, unchanged.
  for (std::size_t i = 0; i < before.size(); ++i) ASSERT_EQ(after[i].timestamp, before[i].timestamp);

  // The map goes on from the stored one: its keyframes first, then those made after the takeover.
  const msgs::FusionMap map = replica_b->map(kRobot, id).value();
  ASSERT_TRUE(map.lidar_keyframes);
  const auto& saved_keyframes = saved_map.lidar_keyframes->keyframes;
  ASSERT_GT(map.lidar_keyframes->keyframes.size(), saved_keyframes.size());
  for (std::size_t k = 0; k < saved_keyframes.size(); ++k) EXPECT_EQ(map.lidar_keyframes->keyframes[k].time, saved_keyframes[k].time);

  // After the takeover the stored poses continue in the session's frame: compared with the
  // uninterrupted drive at the same times (the warehouse robot, 10 s after the takeover).
  const Timestamp resumed = after[before.size()].timestamp;
  const Gaps gaps = gaps_from(uninterrupted, after, resumed);
  const Gaps floor = gaps_from(uninterrupted, uninterrupted_runs.back(), resumed);
  ASSERT_GT(gaps.compared, 500U);
  RecordProperty("takeover_mean_gap_m", std::to_string(gaps.mean));
  RecordProperty("takeover_max_gap_m", std::to_string(gaps.largest));
  RecordProperty("uninterrupted_runs_mean_gap_m", std::to_string(floor.mean));
  RecordProperty("uninterrupted_runs_max_gap_m", std::to_string(floor.largest));
  std::printf("after the takeover: %zu poses compared, mean %.3f m, max %.3f m from the uninterrupted run (a second uninterrupted run: mean %.3f m, max %.3f m)\n",
              gaps.compared, gaps.mean, gaps.largest, floor.mean, floor.largest);
  // Measured 0.011-0.015 m mean, 0.042-0.077 m at most over the 10 s after the takeover (two
  // uninterrupted runs: 0.002-0.004 m mean, 0.022-0.042 m at most); a loaded machine skips more
  // sweeps: room for that.
  EXPECT_LT(gaps.mean, 0.10);
  EXPECT_LT(gaps.largest, 0.30);
}

// A gRPC stream reaching another replica than the one serving its session (the load balancer's
// choice) moves the session there: the holder commits its poses, releases the lease and stops
// serving it; the stream's replica serves it from then on and its stored trajectory goes on.
TEST(Replicas, ASessionMovesToTheReplicaItsStreamReaches) {
  const auto dir = testing::scratch_dir();
  auto replica_a = open_replica(dir, "a");
  auto replica_b = open_replica(dir, "b");
  ASSERT_TRUE(replica_a && replica_b);
  const std::vector<testing::TimedMessage> recording = testing::sample_recording();
  const std::string id = replica_a->create_session(kRobot, {"moving", testing::read_text("examples/data/fusion.yaml"), ""}).value().id;
  const std::size_t half = recording.size() / 2;
  for (std::size_t i = 0; i < half; ++i) ASSERT_TRUE(replica_a->push(kRobot, id, recording[i].sensor, recording[i].message).ok());
  const uint64_t poses_on_a = replica_a->session_info(kRobot, id)->summary.poses;

  // Without a way to ask a, b only names it.
  const ApiStatus named = replica_b->serve_here(kRobot, id);
  ASSERT_FALSE(named.ok());
  EXPECT_EQ(named.error().served_by, "http://a.invalid:8083");
  const Principal stranger{"intruder", "globex", static_cast<uint32_t>(Permission::kAdmin)};
  EXPECT_EQ(replica_b->serve_here(stranger, id).error().code, ErrorCode::kNotFound);

  replica_b.reset();
  SessionManagerConfig config;
  config.storage_flush_interval = std::chrono::milliseconds(5);
  config.replica = {"b", "http://b.invalid:8083", std::chrono::milliseconds(1000), [&](const SessionLease& lease) -> Status {
                      EXPECT_EQ(lease.owner, "a");
                      const ApiStatus handed = replica_a->hand_over(lease.session_id, "b", "http://b.invalid:8083");
                      if (!handed) return Error(handed.error().message);
                      return ok_status();
                    }};
  replica_b = std::move(SessionManager::create(config, open_storage("sqlite://" + (dir / "fusion.db").string()).value(),
                                               std::make_shared<MetricsRegistry>())).value();
  const ApiStatus moved = replica_b->serve_here(kRobot, id);
  ASSERT_TRUE(moved.ok()) << moved.error().message;
  EXPECT_EQ(replica_b->session_info(kRobot, id)->replica, "b");
  // a lets go: its writes are refused with the reason, its reads point to b.
  const ApiStatus refused = replica_a->push(kRobot, id, recording[half].sensor, recording[half].message);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.error().code, ErrorCode::kUnavailable);
  EXPECT_EQ(replica_a->session_info(kRobot, id).error().served_by, "http://b.invalid:8083");
  EXPECT_GE(stored_trajectory(*replica_b, id).size(), poses_on_a) << "every pose a emitted was committed before it let go";

  for (std::size_t i = half; i < recording.size(); ++i) ASSERT_TRUE(replica_b->push(kRobot, id, recording[i].sensor, recording[i].message).ok());
  ASSERT_TRUE(replica_b->flush_storage().ok());
  EXPECT_GT(stored_trajectory(*replica_b, id).size(), poses_on_a + 500);
  ASSERT_TRUE(replica_b->end_session(kRobot, id).ok());
}

}  // namespace
}  // namespace hanzo::fusion::service
