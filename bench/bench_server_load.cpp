// Server load test (issue: "20 concurrent sessions each streaming IMU at 200 Hz plus LiDAR at
// 10 Hz (about 30k points per scan) for 60 s"): a server (SessionManager + gRPC on loopback,
// SQLite storage) in this process, and N client sessions in a forked client process, each
// replaying the simulated warehouse drive (IMU 200 Hz + VLP-16, ~28k points per sweep) in real
// time over StreamImu / StreamPointCloud, stamped with this machine's clock (live data). Both
// processes share this machine's cores.
//
//   build/bench/bench_server_load [--sessions 20] [--seconds 60] [--no-lidar] [--point3] [--default-malloc] [--stagger] [--json]
//   build/bench/bench_server_load --endpoint http://127.0.0.1:8083,127.0.0.1:8084 [--server-pids 11,12,13] ...
//
// --endpoint streams into a running deployment instead (a server, or replicas behind nginx:
// scripts/replicas.sh, bench/replicas_bench.sh): sessions are created over REST, their state read
// back over REST; the server CPU is that of the --server-pids processes (the replicas).
//
// By default every session replays the drive in step with the others (all sweeps of all
// sessions arrive within a millisecond: the worst case); --stagger starts session k k/N of a
// sweep period later, as independent robots' LiDARs spin out of phase.
// Sweeps go as packed_points (what FusionClient sends); --point3 sends the spec's Point3 list.
// The server tunes malloc as hanzo-fusion serve does; --default-malloc measures without that.
//
// Reports: messages sent, received by the sessions, rejected by reason (lost), LiDAR sweeps
// registered; pose latency = from writing an IMU message to reading back the PoseEstimate of its
// timestamp on the same stream (client side, loopback both ways) p50 / p99 / max; the server's
// own push->pose histogram; the server process's CPU and memory (peak, and resident at the end),
// and the client process's CPU.
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/msgs/convert.hpp"
#include "hanzo/fusion/service/allocator_tuning.hpp"
#include "hanzo/fusion/service/fusion_client.hpp"
#include "hanzo/fusion/service/grpc_server.hpp"
#include "hanzo/fusion/service/session_manager.hpp"
#include "hanzo/fusion/service/storage.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "hanzo/fusion/v1/service.grpc.pb.h"

namespace hf = hanzo::fusion;
using Clock = std::chrono::steady_clock;

namespace {

hf::sim::Scenario load_scenario(double seconds, bool lidar) {
  hf::sim::Scenario scenario = hf::sim::load_scenario(std::string(HANZO_SOURCE_DIR) + "/examples/scenarios/warehouse_robot.yaml").value();
  std::erase_if(scenario.sensors, [lidar](const hf::sim::ScenarioSensor& s) {
    return s.modality != hf::config::SensorModality::kImu && !(lidar && s.modality == hf::config::SensorModality::kLidar);
  });
  scenario.duration = seconds;
  return scenario;
}

struct Recording {
  std::vector<std::pair<std::string, hf::msgs::SensorMessage>> messages;  // sensor, message; time order
  std::size_t points_per_sweep = 0;
  double lidar_rate_hz = 10.0;
};

Recording simulate(const hf::sim::Scenario& scenario) {
  Recording out;
  auto simulation = hf::sim::ScenarioSimulation::create(scenario).value();
  for (const hf::sim::ScenarioSensor& sensor : scenario.sensors) {
    if (sensor.modality == hf::config::SensorModality::kLidar) out.lidar_rate_hz = sensor.rate_hz();
  }
  std::size_t sweeps = 0, points = 0;
  (void)simulation->run([&](const hf::sim::ScenarioSensor& sensor, hf::msgs::SensorMessage&& message) -> hf::Status {
    if (const auto* sweep = std::get_if<hf::msgs::PointCloudMessage>(&message)) {
      ++sweeps;
      points += sweep->points.size();
    }
    out.messages.emplace_back(sensor.name, std::move(message));
    return hf::ok_status();
  });
  out.points_per_sweep = sweeps ? points / sweeps : 0;
  return out;
}

double cpu_seconds(const rusage& u) {
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double cpu_seconds_now() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return cpu_seconds(usage);
}

double resident_mb() {  // current RSS of this process
  long pages = 0, resident = 0;
  if (FILE* statm = std::fopen("/proc/self/statm", "r")) {
    if (std::fscanf(statm, "%ld %ld", &pages, &resident) != 2) resident = 0;
    std::fclose(statm);
  }
  return static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE)) / (1024.0 * 1024.0);
}

double percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  return values[std::min(values.size() - 1, static_cast<std::size_t>(p * static_cast<double>(values.size())))];
}

struct ClientResult {
  uint64_t attempted = 0, attempted_lidar = 0;  ///< messages of the recording written (or tried: a broken stream refuses writes)
  uint64_t sent_imu = 0, sent_lidar = 0, poses = 0, late_writes = 0;
  std::vector<double> latencies_s;
  std::vector<std::string> stream_errors;  ///< streams that did not finish OK: "code: message"
};

// Replays the recording in real time into one session over two streams.
ClientResult run_client(hf::v1::FusionService::Stub& stub, const std::string& session_id, const Recording& recording,
                        hf::msgs::PointEncoding point_encoding, std::chrono::nanoseconds start_delay) {
  ClientResult result;
  struct Stream {
    grpc::ClientContext context;
    std::thread reader;
  };
  Stream imu_stream, lidar_stream;
  for (Stream* s : {&imu_stream, &lidar_stream}) s->context.AddMetadata("x-session-id", session_id);
  auto imu = stub.StreamImu(&imu_stream.context);
  auto lidar = stub.StreamPointCloud(&lidar_stream.context);
  std::mutex mutex;
  std::map<int64_t, Clock::time_point> sent_at;  // IMU timestamp -> write time
  std::atomic<uint64_t> poses{0};
  imu_stream.reader = std::thread([&] {
    hf::v1::PoseEstimate pose;
    while (imu->Read(&pose)) {
      const auto now = Clock::now();
      ++poses;
      std::lock_guard lock(mutex);
      const auto found = sent_at.find(static_cast<int64_t>(pose.timestamp_ns()));
      if (found == sent_at.end()) continue;
      result.latencies_s.push_back(std::chrono::duration<double>(now - found->second).count());
      sent_at.erase(sent_at.begin(), std::next(found));
    }
  });
  lidar_stream.reader = std::thread([&] {
    hf::v1::PoseEstimate pose;
    while (lidar->Read(&pose)) ++poses;
  });
  hf::v1::PointCloudMessage sweep_proto;
  const auto started = Clock::now() + start_delay;
  const hf::Timestamp first = hf::msgs::timestamp_of(recording.messages.front().second);
  // Live data: stamped by this machine's clock, as a robot's synchronized sensors are (the
  // server sheds load only for live data; recorded data waits).
  const uint64_t restamp = static_cast<uint64_t>(
      (hf::Timestamp::wall_clock_now() + hf::Duration::from_nanoseconds(start_delay.count()) - first).nanoseconds());
  for (const auto& [sensor, message] : recording.messages) {
    const hf::Timestamp time = hf::msgs::timestamp_of(message);
    const auto due = started + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>((time - first).seconds()));
    if (Clock::now() > due + std::chrono::milliseconds(20)) ++result.late_writes;
    std::this_thread::sleep_until(due);
    if (const auto* imu_message = std::get_if<hf::msgs::ImuMessage>(&message)) {
      hf::v1::ImuMessage imu_proto = hf::msgs::to_proto(*imu_message);
      imu_proto.set_timestamp_ns(imu_proto.timestamp_ns() + restamp);
      {
        std::lock_guard lock(mutex);
        sent_at[static_cast<int64_t>(imu_proto.timestamp_ns())] = Clock::now();
      }
      ++result.attempted;
      if (imu->Write(imu_proto)) ++result.sent_imu;
    } else if (const auto* sweep = std::get_if<hf::msgs::PointCloudMessage>(&message)) {
      hf::msgs::to_proto(*sweep, &sweep_proto, point_encoding);  // reuses the storage, as FusionClient does
      sweep_proto.set_timestamp_ns(sweep_proto.timestamp_ns() + restamp);
      for (uint64_t& point_time : *sweep_proto.mutable_point_timestamps()) point_time += restamp;
      ++result.attempted;
      ++result.attempted_lidar;
      if (lidar->Write(sweep_proto)) ++result.sent_lidar;
    }
  }
  imu->WritesDone();
  lidar->WritesDone();
  imu_stream.reader.join();
  lidar_stream.reader.join();
  // A stream the server (or the proxy) ended early took the messages written into its buffers
  // with it: Write returned true for them.
  const grpc::Status imu_status = imu->Finish(), lidar_status = lidar->Finish();
  for (const grpc::Status& status : {imu_status, lidar_status}) {
    if (!status.ok()) result.stream_errors.push_back(fmt::format("{}: {}", static_cast<int>(status.error_code()), status.error_message()));
  }
  result.poses = poses.load();
  return result;
}

// Streams every session at once into the gRPC server at `address`; the clients' summary.
nlohmann::json stream_sessions(const std::string& address, const std::vector<std::string>& ids, const Recording& recording,
                               hf::msgs::PointEncoding point_encoding, bool stagger) {
  auto stub = hf::v1::FusionService::NewStub(grpc::CreateChannel(address, grpc::InsecureChannelCredentials()));
  const double cpu_before = cpu_seconds_now();
  const auto started = Clock::now();
  std::vector<ClientResult> results(ids.size());
  std::vector<std::thread> clients;
  const double sweep_period = 1.0 / recording.lidar_rate_hz;
  for (std::size_t s = 0; s < ids.size(); ++s) {
    const auto delay = std::chrono::duration_cast<std::chrono::nanoseconds>(
        std::chrono::duration<double>(stagger ? sweep_period * static_cast<double>(s) / static_cast<double>(ids.size()) : 0.0));
    clients.emplace_back([&, s, delay] { results[s] = run_client(*stub, ids[s], recording, point_encoding, delay); });
  }
  for (std::thread& client : clients) client.join();
  const double wall = std::chrono::duration<double>(Clock::now() - started).count();
  // Sent: every message of the recording, whether its stream took it or not (a stream cut by
  // the server or the proxy refuses the writes after the cut: those messages are lost too).
  uint64_t sent = 0, sent_lidar = 0, written = 0, poses_back = 0, late_writes = 0;
  std::vector<double> latencies;
  nlohmann::json stream_errors = nlohmann::json::array();
  for (const ClientResult& r : results) {
    for (const std::string& error : r.stream_errors) stream_errors.push_back(error);
    sent += r.attempted;
    sent_lidar += r.attempted_lidar;
    written += r.sent_imu + r.sent_lidar;
    poses_back += r.poses;
    late_writes += r.late_writes;
    latencies.insert(latencies.end(), r.latencies_s.begin(), r.latencies_s.end());
  }
  const nlohmann::json summary = {{"points_per_sweep", recording.points_per_sweep}, {"messages_sent", sent}, {"lidar_sweeps_sent", sent_lidar},
                                  {"messages_refused_by_streams", sent - written},
                                  {"poses_back", poses_back}, {"client_writes_late_20ms", late_writes},
                                  {"pose_latency_p50_ms", 1e3 * percentile(latencies, 0.5)}, {"pose_latency_p99_ms", 1e3 * percentile(latencies, 0.99)},
                                  {"pose_latency_max_ms", 1e3 * percentile(latencies, 1.0)}, {"wall_seconds", wall},
                                  {"client_cpu_cores_used", (cpu_seconds_now() - cpu_before) / wall}, {"stream_errors", stream_errors}};
  return summary;
}

// The client process: simulates the drive, waits for "PORT ID..." on `commands`, streams every
// session at once, and writes its summary (one JSON object) to `report`.
int run_clients(int commands, int report, const hf::sim::Scenario& scenario, int sessions, hf::msgs::PointEncoding point_encoding,
                bool stagger) {
  const Recording recording = simulate(scenario);
  std::string line;
  char c = 0;
  while (read(commands, &c, 1) == 1 && c != '\n') line += c;
  std::istringstream words(line);
  int port = 0;
  words >> port;
  std::vector<std::string> ids(static_cast<std::size_t>(sessions));
  for (std::string& id : ids) words >> id;
  if (!port || ids.back().empty()) return 1;
  const std::string text = stream_sessions("127.0.0.1:" + std::to_string(port), ids, recording, point_encoding, stagger).dump();
  return write(report, text.data(), text.size()) == static_cast<ssize_t>(text.size()) ? 0 : 1;
}

// CPU seconds (user + system) the processes used so far (/proc/PID/stat).
double processes_cpu_seconds(const std::vector<int>& pids) {
  double total = 0.0;
  for (int pid : pids) {
    std::FILE* file = std::fopen(fmt::format("/proc/{}/stat", pid).c_str(), "r");
    if (file == nullptr) continue;
    char text[4096] = {};
    const std::size_t n = std::fread(text, 1, sizeof(text) - 1, file);
    std::fclose(file);
    const char* after_name = std::strrchr(text, ')');  // the command name may hold spaces
    if (after_name == nullptr || n == 0) continue;
    std::istringstream fields(after_name + 2);
    std::string field;
    unsigned long long user = 0, system = 0;
    for (int i = 3; i <= 15 && fields >> field; ++i) {  // fields 14, 15: utime, stime
      if (i == 14) user = std::stoull(field);
      if (i == 15) system = std::stoull(field);
    }
    total += static_cast<double>(user + system) / static_cast<double>(sysconf(_SC_CLK_TCK));
  }
  return total;
}

// --endpoint: sessions created in a running deployment over REST, streamed over gRPC, their
// state read back over REST.
int run_against(const std::string& endpoint, const std::vector<int>& server_pids, const hf::sim::Scenario& scenario, int sessions,
                hf::msgs::PointEncoding point_encoding, bool stagger, bool json_output) {
  const std::size_t comma = endpoint.find(',');
  if (comma == std::string::npos) {
    std::fprintf(stderr, "--endpoint: expected REST_URL,GRPC_ADDRESS\n");
    return 2;
  }
  hf::service::FusionClientConfig client_config;
  client_config.rest_url = endpoint.substr(0, comma);
  client_config.grpc_address = endpoint.substr(comma + 1);
  auto client = hf::service::FusionClient::create(client_config);
  if (!client) {
    std::fprintf(stderr, "%s\n", client.error().message.c_str());
    return 1;
  }
  std::fprintf(stderr, "simulating %.0f s of the warehouse drive...\n", scenario.duration.value_or(0.0));
  const Recording recording = simulate(scenario);
  const std::string config_yaml = hf::config::to_yaml(hf::sim::scenario_fusion_config(scenario));
  const std::string calibration_yaml = hf::calib::to_yaml(hf::sim::scenario_calibration(scenario));
  std::vector<std::string> ids;
  for (int s = 0; s < sessions; ++s) {
    auto id = client.value()->create_session(fmt::format("load-{}", s), config_yaml, calibration_yaml);
    if (!id) {
      std::fprintf(stderr, "%s\n", id.error().message.c_str());
      return 1;
    }
    ids.push_back(*id);
  }
  const double server_cpu_before = processes_cpu_seconds(server_pids);
  nlohmann::json result = stream_sessions(client_config.grpc_address, ids, recording, point_encoding, stagger);
  const double wall = result["wall_seconds"].get<double>();
  const double server_cpu = processes_cpu_seconds(server_pids) - server_cpu_before;
  // The sessions' counts, read until two reads 0.5 s apart agree (a replica behind on its queue
  // still takes in messages the clients finished writing; the poses queued are committed every
  // 20 ms), at most 20 s.
  uint64_t received = 0, registered = 0, stored = 0, rejected_total = 0, aligning = 0;
  std::map<std::string, uint64_t> replicas;
  double settle_seconds = 0.0;
  for (int read = 0; read < 40; ++read) {
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    const uint64_t previous = received + stored;
    received = registered = stored = rejected_total = aligning = 0;
    replicas.clear();
    for (const std::string& id : ids) {
      auto body = client.value()->get("/v1/sessions/" + id);
      if (!body) {
        std::fprintf(stderr, "%s\n", body.error().message.c_str());
        return 1;
      }
      const nlohmann::json session = nlohmann::json::parse(*body);
      for (const nlohmann::json& sensor : session["sensors"]) {
        received += sensor["received"].get<uint64_t>();
        for (const auto& [reason, count] : sensor["rejected"].items()) (reason == "aligning" ? aligning : rejected_total) += count.get<uint64_t>();
      }
      registered += session["mapping"]["scans_registered"].get<uint64_t>();
      stored += session["stored_poses"].get<uint64_t>();
      ++replicas[session["replica"].is_string() ? session["replica"].get<std::string>() : "single server"];
    }
    settle_seconds = 0.5 * (read + 1);
    if (read > 0 && received + stored == previous) break;
  }
  const uint64_t sent = result["messages_sent"].get<uint64_t>();
  result.update(nlohmann::json{{"sessions", sessions}, {"seconds", scenario.duration.value_or(0.0)}, {"endpoint", endpoint},
                               {"sessions_by_replica", replicas}, {"messages_received", received}, {"messages_lost_in_transport", sent - received},
                               {"messages_rejected", rejected_total}, {"messages_aligning", aligning}, {"lidar_sweeps_registered", registered},
                               {"poses_stored", stored}, {"server_cpu_cores_used", server_cpu / wall}, {"counts_settled_after_s", settle_seconds}});
  if (json_output) {
    std::printf("%s\n", result.dump().c_str());
  } else {
    std::printf("| sessions | replicas (sessions each) | messages sent | received | lost | rejected (+ aligning) | LiDAR registered | pose latency p50 / p99 / max | servers' CPU | clients' CPU |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|\n");
    std::string spread;
    for (const auto& [replica, count] : replicas) spread += fmt::format("{}{} {}", spread.empty() ? "" : ", ", replica, count);
    std::printf("| %d | %s | %lu | %lu | %lu | %lu (+ %lu) | %lu / %lu | %.2f / %.1f / %.0f ms | %.2f cores | %.2f cores |\n", sessions, spread.c_str(),
                static_cast<unsigned long>(sent), static_cast<unsigned long>(received), static_cast<unsigned long>(sent - received),
                static_cast<unsigned long>(rejected_total), static_cast<unsigned long>(aligning), static_cast<unsigned long>(registered),
                static_cast<unsigned long>(result["lidar_sweeps_sent"].get<uint64_t>()), result["pose_latency_p50_ms"].get<double>(),
                result["pose_latency_p99_ms"].get<double>(), result["pose_latency_max_ms"].get<double>(), server_cpu / wall,
                result["client_cpu_cores_used"].get<double>());
    std::printf("counts settled %.1f s after the streams ended; %zu streams ended with an error%s\n", settle_seconds, result["stream_errors"].size(),
                result["stream_errors"].empty() ? "" : fmt::format(" (first: {})", result["stream_errors"][0].get<std::string>()).c_str());
  }
  return sent == received ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  int sessions = 20;
  double seconds = 60.0;
  bool lidar = true, json_output = false, default_malloc = false, stagger = false;
  std::string endpoint;
  std::vector<int> server_pids;
  hf::msgs::PointEncoding point_encoding = hf::msgs::PointEncoding::kPacked;
  for (int i = 1; i < argc; ++i) {
    const std::string argument = argv[i];
    if (argument == "--sessions" && i + 1 < argc) sessions = std::stoi(argv[++i]);
    else if (argument == "--seconds" && i + 1 < argc) seconds = std::stod(argv[++i]);
    else if (argument == "--no-lidar") lidar = false;
    else if (argument == "--json") json_output = true;
    else if (argument == "--point3") point_encoding = hf::msgs::PointEncoding::kPoint3;
    else if (argument == "--default-malloc") default_malloc = true;
    else if (argument == "--stagger") stagger = true;
    else if (argument == "--endpoint" && i + 1 < argc) endpoint = argv[++i];
    else if (argument == "--server-pids" && i + 1 < argc) {
      std::istringstream list(argv[++i]);
      for (std::string pid; std::getline(list, pid, ',');) server_pids.push_back(std::stoi(pid));
    } else {
      std::fprintf(stderr, "usage: bench_server_load [--sessions N] [--seconds S] [--no-lidar] [--point3] [--default-malloc] [--stagger] [--json]\n"
                           "                         [--endpoint REST_URL,GRPC_ADDRESS [--server-pids P1,P2,...]]\n");
      return 2;
    }
  }
  if (sessions < 1) {
    std::fprintf(stderr, "--sessions must be at least 1\n");
    return 2;
  }
  const hf::sim::Scenario scenario = load_scenario(seconds, lidar);
  if (!endpoint.empty()) return run_against(endpoint, server_pids, scenario, sessions, point_encoding, stagger, json_output);
  // Fork before any thread exists: the clients get a process of their own, so that the
  // server's CPU and memory are this process's.
  int to_client[2], from_client[2];
  if (pipe(to_client) != 0 || pipe(from_client) != 0) {
    std::perror("pipe");
    return 1;
  }
  const pid_t client = fork();
  if (client < 0) {
    std::perror("fork");
    return 1;
  }
  if (client == 0) {
    close(to_client[1]);
    close(from_client[0]);
    std::fprintf(stderr, "simulating %.0f s of the warehouse drive...\n", seconds);
    _exit(run_clients(to_client[0], from_client[1], scenario, sessions, point_encoding, stagger));
  }
  close(to_client[0]);
  close(from_client[1]);
  // As hanzo-fusion serve (service/allocator_tuning.hpp); --default-malloc leaves glibc's settings.
  if (!default_malloc) hf::service::keep_large_buffers_on_heap();

  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_bench_server_load_{}", getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  auto metrics = std::make_shared<hf::service::MetricsRegistry>();
  auto manager = hf::service::SessionManager::create({}, hf::service::open_storage("sqlite://" + (dir / "fusion.db").string()).value(),
                                                     metrics).value();
  hf::service::GrpcServerConfig grpc_config;
  grpc_config.bind_address = "127.0.0.1";
  grpc_config.port = 0;
  auto server = hf::service::GrpcServer::create(grpc_config, *manager, nullptr, metrics).value();
  if (auto started = server->start(); !started) {
    std::fprintf(stderr, "%s\n", started.error().message.c_str());
    kill(client, SIGKILL);
    return 1;
  }
  const std::string config_yaml = hf::config::to_yaml(hf::sim::scenario_fusion_config(scenario));
  const std::string calibration_yaml = hf::calib::to_yaml(hf::sim::scenario_calibration(scenario));
  const hf::service::Principal local{"bench", "local", 0xffffffffu};
  std::vector<std::string> ids;
  std::string command = std::to_string(server->port());
  for (int s = 0; s < sessions; ++s) {
    ids.push_back(manager->create_session(local, {fmt::format("load-{}", s), config_yaml, calibration_yaml}).value().id);
    command += " " + ids.back();
  }
  command += "\n";
  const double rss_idle = resident_mb();
  const double cpu_before = cpu_seconds_now();
  if (write(to_client[1], command.data(), command.size()) != static_cast<ssize_t>(command.size())) {
    std::perror("write to the client process");
    kill(client, SIGKILL);
    return 1;
  }
  std::string report;
  char buffer[4096];
  for (ssize_t n; (n = read(from_client[0], buffer, sizeof(buffer))) > 0;) report.append(buffer, static_cast<std::size_t>(n));
  int client_status = 0;
  waitpid(client, &client_status, 0);
  const double server_cpu = cpu_seconds_now() - cpu_before;
  const nlohmann::json clients = nlohmann::json::parse(report, nullptr, false);
  if (!WIFEXITED(client_status) || WEXITSTATUS(client_status) != 0 || clients.is_discarded()) {
    std::fprintf(stderr, "the client process failed\n");
    return 1;
  }
  std::fprintf(stderr, "%d sessions streamed for %.0f s\n", sessions, seconds);
  (void)manager->flush_storage();

  uint64_t received = 0, registered = 0, stored = 0;
  std::map<std::string, uint64_t> rejected;
  for (const std::string& id : ids) {
    const hf::service::SessionInfo info = manager->session_info(local, id).value();
    for (const hf::pipeline::SensorStatistics& sensor : info.summary.sensors) {
      received += sensor.received;
      for (const auto& [reason, count] : sensor.rejected) rejected[sensor.name + ":" + std::string(hf::pipeline::to_string(reason))] += count;
    }
    registered += info.mapping.scans_registered;
    stored += info.stored_poses;
  }
  double server_p50 = 0, server_p99 = 0;
  {
    // The server's push -> pose histogram, all sessions together (bucket upper bounds).
    std::vector<uint64_t> total;
    const hf::service::Histogram* any = nullptr;
    for (const std::string& id : ids) {
      hf::service::Histogram& h = metrics->histogram("hanzo_fusion_pose_latency_seconds", "", hf::service::latency_buckets_seconds(), {{"session", id}});
      any = &h;
      const auto counts = h.cumulative_counts();
      if (total.empty()) total.assign(counts.size(), 0);
      for (std::size_t i = 0; i < counts.size(); ++i) total[i] += counts[i];
    }
    const auto quantile = [&](double p) {  // upper bound of the bucket holding quantile p
      const double target = p * static_cast<double>(total.back());
      for (std::size_t i = 0; i < any->bounds().size(); ++i) {
        if (static_cast<double>(total[i]) >= target) return any->bounds()[i];
      }
      return any->bounds().back();
    };
    server_p50 = quantile(0.5);
    server_p99 = quantile(0.99);
  }
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  const double wall = clients["wall_seconds"].get<double>();
  const uint64_t sent = clients["messages_sent"].get<uint64_t>();
  // The IMU's static alignment (the first second) takes its messages without fusing them.
  uint64_t rejected_total = 0, aligning = 0;
  for (const auto& [reason, count] : rejected) (reason.ends_with(":aligning") ? aligning : rejected_total) += count;

  nlohmann::json result = clients;
  result.update({{"sessions", sessions}, {"seconds", seconds}, {"lidar", lidar},
                 {"point_encoding", point_encoding == hf::msgs::PointEncoding::kPacked ? "packed_points" : "points"}, {"messages_received", received},
                 {"messages_lost_in_transport", sent - received}, {"messages_rejected", rejected},
                 {"lidar_sweeps_registered", registered}, {"poses_stored", stored}, {"server_push_to_pose_p50_ms", 1e3 * server_p50},
                 {"server_push_to_pose_p99_ms", 1e3 * server_p99}, {"server_cpu_cores_used", server_cpu / wall},
                 {"server_peak_rss_mb", static_cast<double>(usage.ru_maxrss) / 1024.0}, {"server_idle_rss_mb", rss_idle},
                 {"server_rss_at_end_mb", resident_mb()}});
  if (json_output) {
    std::printf("%s\n", result.dump().c_str());
  } else {
    std::printf("| sessions | streams | messages sent | received | lost | rejected (+ aligning) | LiDAR registered | pose latency p50 / p99 / max | server push->pose p50 / p99 | server CPU | clients' CPU | server memory idle / peak / end |\n");
    std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    std::printf("| %d | IMU 200 Hz%s | %lu | %lu | %lu | %lu (+ %lu) | %lu / %lu | %.2f / %.1f / %.0f ms | <= %.3f / <= %.3f ms | %.2f cores | %.2f cores | %.0f / %.0f / %.0f MB |\n",
                sessions, lidar ? fmt::format(" + LiDAR 10 Hz ({}k pts, {})", clients["points_per_sweep"].get<std::size_t>() / 1000,
                                    point_encoding == hf::msgs::PointEncoding::kPacked ? "packed" : "Point3").c_str() : "",
                static_cast<unsigned long>(sent), static_cast<unsigned long>(received), static_cast<unsigned long>(sent - received),
                static_cast<unsigned long>(rejected_total), static_cast<unsigned long>(aligning), static_cast<unsigned long>(registered),
                static_cast<unsigned long>(clients["lidar_sweeps_sent"].get<uint64_t>()), clients["pose_latency_p50_ms"].get<double>(),
                clients["pose_latency_p99_ms"].get<double>(), clients["pose_latency_max_ms"].get<double>(), 1e3 * server_p50, 1e3 * server_p99,
                server_cpu / wall, clients["client_cpu_cores_used"].get<double>(), rss_idle, static_cast<double>(usage.ru_maxrss) / 1024.0,
                resident_mb());
    for (const auto& [reason, count] : rejected) std::printf("  rejected %s: %lu\n", reason.c_str(), static_cast<unsigned long>(count));
  }
  server->stop();
  std::filesystem::remove_all(dir);
  return 0;
}
