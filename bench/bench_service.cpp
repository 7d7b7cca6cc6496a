// The server's costs, measured in one run:
//  - StorageAppend: committing PoseEstimates to SQLite (WAL, synchronous=FULL) and to PostgreSQL
//    15 on loopback (a throwaway server started by scripts/test-postgres.sh), in transactions of
//    1, 100 and 1000 poses. Counter: poses per second (the pose recorder commits every 20 ms,
//    so 20 sessions x 200 Hz = 80 poses per commit).
//  - SessionPush: the sample recording (examples/data: IMU 100 Hz, GNSS, wheels) pushed through
//    the SessionManager with every pose stored, the work the server does per message. Counters:
//    messages per second, pose latency p50 / p99 (message in -> PoseEstimate out).
//  - PageCompression: a trajectory page of every stored pose (1,901, 2.4 MB of JSON) compressed
//    at each level of brotli and gzip: the REST server's (brotli quality 1; gzip level 1 for
//    clients without br) against cpp-httplib's own choice (brotli quality 11, its default).
//    Counters: compressed bytes and ratio; time per page.
//  - RestGet: GET requests with auth by wrk (2 threads, 16 connections, 5 s): the pose, the session,
//    a trajectory page, the stored maps, a stored map's versions and the map itself
//    against an in-process RestServer. Counters: requests per second, mean latency.

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>

#include <benchmark/benchmark.h>
#include <brotli/encode.h>
#include <zlib.h>
#include <fmt/format.h>

#include "hanzo/fusion/io/csv_import.hpp"
#include "hanzo/fusion/service/rest_server.hpp"
#include "hanzo/fusion/service/session_manager.hpp"
#include "http_compression.hpp"

// Last: it includes <resolv.h>, whose _res macro breaks Eigen headers included after it.
#include <httplib.h>

namespace {

using namespace hanzo::fusion;
using namespace hanzo::fusion::service;

const Principal kRobot{"bench", "bench", static_cast<uint32_t>(Permission::kAdmin)};

std::string read_text(const std::string& path) {
  std::ifstream file(path);
  return {std::istreambuf_iterator<char>(file), {}};
}

std::string run_command(const std::string& command) {
  std::string output;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return output;
  std::array<char, 4096> buffer{};
  std::size_t n = 0;
  while ((n = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0) output.append(buffer.data(), n);
  pclose(pipe);
  return output;
}

// A PostgreSQL server for the whole run (stopped at exit).
struct PostgresServer {
  std::string dir = fmt::format("/tmp/hanzo-fusion-bench-postgres-{}", getpid());
  std::string url;
  PostgresServer() {
    run_command(fmt::format("{}/scripts/test-postgres.sh start {} >&2", HANZO_SOURCE_DIR, dir));
    url = read_text(dir + "/url");
    while (!url.empty() && url.back() == '\n') url.pop_back();
  }
  ~PostgresServer() { run_command(fmt::format("{}/scripts/test-postgres.sh stop {}", HANZO_SOURCE_DIR, dir)); }
};

const std::string& postgres_url() {
  static PostgresServer server;
  return server.url;
}

std::string scratch(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_bench_service_{}_{}", name, getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

msgs::PoseEstimate make_pose(int64_t ns) {
  msgs::PoseEstimate pose;
  pose.timestamp = Timestamp::from_nanoseconds(ns);
  pose.T_world_body.position = {ns * 1e-9, 0.5, 0.1};
  pose.status.state = msgs::TrackingState::kTracking;
  pose.status.active_sensors = {"imu", "gnss"};
  pose.pose_covariance = msgs::Matrix6d::Identity() * 0.01;
  return pose;
}

void StorageAppend(benchmark::State& state, bool postgres) {
  const std::size_t batch_size = static_cast<std::size_t>(state.range(0));
  const std::string url = postgres ? postgres_url() : "sqlite://" + scratch("sqlite") + "/fusion.db";
  auto storage = open_storage(url);
  if (!storage) {
    state.SkipWithError(storage.error().message.c_str());
    return;
  }
  const std::string session = fmt::format("bench-{}-{}", batch_size, std::random_device{}());
  int64_t t = 1;
  uint64_t poses = 0;
  for (auto _ : state) {
    std::vector<StoredPose> batch;
    for (std::size_t i = 0; i < batch_size; ++i) batch.push_back({session, make_pose(t++ * 1'000'000)});
    if (!storage.value()->append_poses(batch)) state.SkipWithError("append failed");
    poses += batch_size;
  }
  state.counters["poses_per_s"] = benchmark::Counter(static_cast<double>(poses), benchmark::Counter::kIsRate);
}

struct TimedMessage {
  std::string sensor;
  msgs::SensorMessage message;
};

const std::vector<TimedMessage>& sample() {
  static const std::vector<TimedMessage> messages = [] {
    std::vector<TimedMessage> all;
    for (const char* sensor : {"imu", "gnss", "wheels"}) {
      auto read = io::read_sensor_csv(std::string(HANZO_SOURCE_DIR) + "/examples/data/" + sensor + ".csv");
      for (msgs::SensorMessage& message : read.value()) all.push_back({sensor, std::move(message)});
    }
    std::stable_sort(all.begin(), all.end(), [](const auto& a, const auto& b) {
      return msgs::timestamp_of(a.message) < msgs::timestamp_of(b.message);
    });
    return all;
  }();
  return messages;
}

std::unique_ptr<SessionManager> make_manager(const std::string& url, std::shared_ptr<MetricsRegistry> metrics,
                                             const std::string& map_directory = "") {
  SessionManagerConfig config;
  config.map_directory = map_directory;
  auto manager = SessionManager::create(config, open_storage(url).value(), std::move(metrics));
  return std::move(manager).value();
}

// The p-quantile (0..1) of a Prometheus histogram's buckets (upper bound of the bucket holding it).
double histogram_quantile(const std::string& text, const std::string& name, double quantile) {
  std::vector<std::pair<double, double>> buckets;  // le, cumulative count
  const std::regex line(name + R"re(_bucket\{[^}]*le="([^"]+)"\} ([0-9.e+]+))re");
  for (std::sregex_iterator it(text.begin(), text.end(), line), end; it != end; ++it) {
    const std::string le = (*it)[1];
    buckets.emplace_back(le == "+Inf" ? std::numeric_limits<double>::infinity() : std::stod(le), std::stod((*it)[2]));
  }
  if (buckets.empty() || buckets.back().second == 0) return 0.0;
  const double target = quantile * buckets.back().second;
  for (const auto& [le, count] : buckets) {
    if (count >= target) return le;
  }
  return buckets.back().first;
}

void SessionPush(benchmark::State& state, bool postgres) {
  const std::vector<TimedMessage>& messages = sample();
  const std::string config = read_text(std::string(HANZO_SOURCE_DIR) + "/examples/data/fusion.yaml");
  auto metrics = std::make_shared<MetricsRegistry>();
  auto manager = make_manager(postgres ? postgres_url() : "sqlite://" + scratch("push") + "/fusion.db", metrics);
  uint64_t pushed = 0;
  for (auto _ : state) {
    const std::string id = manager->create_session(kRobot, {"bench", config, ""}).value().id;
    for (const TimedMessage& message : messages) {
      (void)manager->push(kRobot, id, message.sensor, message.message);
      ++pushed;
    }
    state.PauseTiming();
    (void)manager->flush_storage();
    (void)manager->end_session(kRobot, id);
    state.ResumeTiming();
  }
  (void)manager->flush_storage();
  state.counters["messages_per_s"] = benchmark::Counter(static_cast<double>(pushed), benchmark::Counter::kIsRate);
  // Latency histograms of ended sessions are removed; measure one more live session.
  const std::string id = manager->create_session(kRobot, {"bench", config, ""}).value().id;
  for (const TimedMessage& message : messages) (void)manager->push(kRobot, id, message.sensor, message.message);
  const std::string text = metrics->render();
  state.counters["pose_latency_p50_us"] = 1e6 * histogram_quantile(text, "hanzo_fusion_pose_latency_seconds", 0.5);
  state.counters["pose_latency_p99_us"] = 1e6 * histogram_quantile(text, "hanzo_fusion_pose_latency_seconds", 0.99);
}

// GET requests by wrk (2 threads, 16 connections, 5 s) with auth; range(0) picks the route:
// 0 the latest pose, 1 the session, 2 a page of 100 stored poses, 3 the stored maps, 4 a stored
// map's versions (json), 5 the stored map itself (a FusionMap of 20k points).
void RestGet(benchmark::State& state) {
  if (run_command("command -v wrk").empty()) {
    state.SkipWithError("wrk is not installed");
    return;
  }
  auto metrics = std::make_shared<MetricsRegistry>();
  const std::string dir = scratch("rest");
  auto manager = make_manager("sqlite://" + dir + "/fusion.db", metrics, dir + "/maps");
  const std::string id =
      manager->create_session(kRobot, {"bench", read_text(std::string(HANZO_SOURCE_DIR) + "/examples/data/fusion.yaml"), ""}).value().id;
  for (const TimedMessage& message : sample()) (void)manager->push(kRobot, id, message.sensor, message.message);
  (void)manager->flush_storage();
  msgs::FusionMap map;
  map.map_id = "bench-map";
  map.points.emplace();
  for (int i = 0; i < 20000; ++i) map.points->points.emplace_back(0.1f * static_cast<float>(i % 200), 0.1f * static_cast<float>(i / 200), 0.0f);
  (void)manager->load_map(kRobot, map);
  const std::string token = "bench-token-0123456789";
  auto tokens = std::make_shared<TokenStore>(TokenStore::parse_inline(token + "=bench:fusion:session:read,fusion:map:read").value());
  RestServerConfig config;
  config.bind_address = "127.0.0.1";
  config.port = 0;
  auto rest = RestServer::create(config, *manager, tokens, metrics).value();
  (void)rest->start();
  const std::vector<std::string> paths = {"/v1/sessions/" + id + "/pose", "/v1/sessions/" + id, "/v1/sessions/" + id + "/trajectory?limit=100",
                                          "/v1/maps", "/v1/maps/bench-map?format=json", "/v1/maps/bench-map"};
  const std::string& path = paths.at(static_cast<std::size_t>(state.range(0)));
  double requests_per_s = 0.0;
  double latency_ms = 0.0;
  for (auto _ : state) {
    const std::string output =
        run_command(fmt::format("wrk -t2 -c16 -d5s -H 'Authorization: Bearer {}' 'http://127.0.0.1:{}{}'", token, rest->port(), path));
    std::smatch match;
    if (std::regex_search(output, match, std::regex(R"(Requests/sec:\s+([0-9.]+))"))) requests_per_s = std::stod(match[1]);
    if (std::regex_search(output, match, std::regex(R"(Latency\s+([0-9.]+)(us|ms|s))"))) {
      latency_ms = std::stod(match[1]) * (match[2] == "us" ? 1e-3 : match[2] == "s" ? 1e3 : 1.0);
    }
    if (output.find("Non-2xx") != std::string::npos) state.SkipWithError(("non-2xx answers from " + path).c_str());
  }
  state.counters["requests_per_s"] = requests_per_s;
  state.counters["mean_latency_ms"] = latency_ms;
  const std::vector<std::string> names = {"pose", "session", "trajectory page of 100", "stored maps", "map versions (json)",
                                          "map file (20k points)"};
  state.SetLabel(names.at(static_cast<std::size_t>(state.range(0))));
}

// The trajectory page of every pose of the sample recording, as GET /trajectory returns it.
const std::string& trajectory_page() {
  static const std::string page = [] {
    auto metrics = std::make_shared<MetricsRegistry>();
    const std::string dir = scratch("compression");
    auto manager = make_manager("sqlite://" + dir + "/fusion.db", metrics);
    const std::string id =
        manager->create_session(kRobot, {"bench", read_text(std::string(HANZO_SOURCE_DIR) + "/examples/data/fusion.yaml"), ""}).value().id;
    for (const TimedMessage& message : sample()) (void)manager->push(kRobot, id, message.sensor, message.message);
    (void)manager->flush_storage();
    RestServerConfig config;
    config.bind_address = "127.0.0.1";
    config.port = 0;
    const std::string token = "bench-token-0123456789";
    auto tokens = std::make_shared<TokenStore>(TokenStore::parse_inline(token + "=bench:fusion:session:read").value());
    auto rest = RestServer::create(config, *manager, tokens, metrics).value();
    (void)rest->start();
    httplib::Client http("127.0.0.1", rest->port());
    const auto got = http.Get(("/v1/sessions/" + id + "/trajectory?limit=10000").c_str(),  // no Accept-Encoding: plain
                              httplib::Headers{{"Authorization", "Bearer " + token}});
    rest->stop();
    return got && got->status == 200 ? got->body : std::string();
  }();
  return page;
}

// range(0): 0 brotli, 1 gzip; range(1): the level (brotli quality 0..11, gzip 1..9). The server
// sends brotli quality 1 (gzip 1 to clients without br); cpp-httplib's own choice is brotli 11.
void PageCompression(benchmark::State& state) {
  const std::string& body = trajectory_page();
  if (body.empty()) {
    state.SkipWithError("the trajectory page could not be read");
    return;
  }
  const bool brotli = state.range(0) == 0;
  const int level = static_cast<int>(state.range(1));
  std::size_t compressed_bytes = 0;
  for (auto _ : state) {
    if (brotli) {
      std::size_t size = BrotliEncoderMaxCompressedSize(body.size());
      std::string out(size, '\0');
      BrotliEncoderCompress(level, BROTLI_DEFAULT_WINDOW, BROTLI_MODE_TEXT, body.size(), reinterpret_cast<const uint8_t*>(body.data()), &size,
                            reinterpret_cast<uint8_t*>(out.data()));
      compressed_bytes = size;
    } else {
      uLongf size = compressBound(static_cast<uLong>(body.size()));
      std::string out(size, '\0');
      compress2(reinterpret_cast<Bytef*>(out.data()), &size, reinterpret_cast<const Bytef*>(body.data()), static_cast<uLong>(body.size()), level);
      compressed_bytes = size;
    }
  }
  state.counters["page_bytes"] = static_cast<double>(body.size());
  state.counters["compressed_bytes"] = static_cast<double>(compressed_bytes);
  state.counters["ratio"] = static_cast<double>(body.size()) / static_cast<double>(std::max<std::size_t>(compressed_bytes, 1));
  const auto server = detail::compress(body, brotli ? detail::ContentEncoding::kBrotli : detail::ContentEncoding::kGzip);
  const bool chosen = server && (brotli ? server->size() == compressed_bytes : std::abs(static_cast<double>(server->size()) - static_cast<double>(compressed_bytes)) < 32.0);
  state.SetLabel(fmt::format("{} {}{}", brotli ? "brotli" : "gzip", level,
                             chosen ? " (hanzo-fusion's)" : brotli && level == BROTLI_DEFAULT_QUALITY ? " (cpp-httplib's)" : ""));
}

BENCHMARK_CAPTURE(StorageAppend, sqlite, false)->Arg(1)->Arg(100)->Arg(1000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(StorageAppend, postgresql, true)->Arg(1)->Arg(100)->Arg(1000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(SessionPush, sqlite, false)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK_CAPTURE(SessionPush, postgresql, true)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(PageCompression)->ArgsProduct({{0}, {1, 2, 3, 4, 5, 11}})->ArgsProduct({{1}, {1, 4, 6}})->Unit(benchmark::kMillisecond);
BENCHMARK(RestGet)->DenseRange(0, 5)->Unit(benchmark::kSecond)->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
