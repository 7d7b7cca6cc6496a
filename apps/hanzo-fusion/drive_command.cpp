// hanzo-fusion drive --config fusion.yaml (--record LOG.mcap | --out DIR | --server HOST:PORT)
// [--calib C] [--duration S]: the live sensors of the configuration (fusion.sensors.<name>.driver:
// a driver and its udp:// / tcp:// / serial:// source) read on one thread each, decoded, written
// to a sensor log on the sensors' topics, fused by a Session as `run` fuses a log (every message
// in arrival order; DIR/trajectory.tum) and / or sent to a server session over gRPC (one stream
// per sensor; a session created from --config and --calib unless --session names one).
// Runs for --duration seconds or until SIGINT / SIGTERM. A sensor that stays silent longer than
// its timeout is reported (once per silence) and the others go on; a malformed packet or
// sentence is counted and skipped. Exit 0 when every sensor delivered messages; 1 otherwise
// (the log is kept, the report names the silent sensors).
#include <signal.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/drivers/byte_source.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "live_decoder.hpp"
#include "log_writing.hpp"
#ifdef HANZO_FUSION_WITH_SERVICE
#include "server_session.hpp"
#endif

namespace hanzo::fusion::app {

namespace {

struct DriveOptions {
  std::string config;
  std::string calibration;
  std::string record;
  std::string out;
  double duration = 0.0;  // s; 0: until SIGINT / SIGTERM
#ifdef HANZO_FUSION_WITH_SERVICE
  ServerOptions server;   // --server: into a server session over gRPC
#endif
};

/// One live sensor: its source, decoder and counts (the counts read under `mutex`).
struct LiveSensor {
  const config::SensorConfig* sensor = nullptr;
  std::unique_ptr<drivers::ByteSource> source;
  std::unique_ptr<LiveDecoder> decoder;
  std::mutex mutex;
  std::vector<msgs::SensorMessage> ready;  // decoded, not yet written
  uint64_t reads = 0, bytes = 0, messages = 0, silences = 0;
  std::string stream_error;
};

std::atomic<bool> stop_requested{false};
extern "C" void request_stop(int) { stop_requested = true; }

void read_sensor(LiveSensor& live, const std::atomic<bool>& stop) {
  const double timeout = live.sensor->effective_timeout_s();
  auto last_data = std::chrono::steady_clock::now();
  bool silent = false;
  std::vector<msgs::SensorMessage> decoded;
  while (!stop) {
    Result<std::optional<drivers::ReceivedBytes>> received = live.source->read(std::chrono::milliseconds(100));
    if (!received) {
      std::lock_guard lock(live.mutex);
      live.stream_error = received.error().message;
      logger()->error("drive: sensor {}: {}", live.sensor->name, received.error().message);
      return;
    }
    const auto now = std::chrono::steady_clock::now();
    if (!*received) {
      if (!silent && std::chrono::duration<double>(now - last_data).count() > timeout) {
        silent = true;
        std::lock_guard lock(live.mutex);
        ++live.silences;
        logger()->warn("drive: sensor {} silent for more than {:.2f} s ({})", live.sensor->name, timeout, live.source->address().url);
      }
      continue;
    }
    last_data = now;
    silent = false;
    live.decoder->decode(**received, decoded);
    std::lock_guard lock(live.mutex);
    ++live.reads;
    live.bytes += (*received)->bytes.size();
    live.messages += decoded.size();
    for (msgs::SensorMessage& message : decoded) live.ready.push_back(std::move(message));
    decoded.clear();
  }
  live.decoder->flush(decoded);
  std::lock_guard lock(live.mutex);
  live.messages += decoded.size();
  for (msgs::SensorMessage& message : decoded) live.ready.push_back(std::move(message));
}

int run_drive(const Output& output, const DriveOptions& options) {
  nlohmann::json result = {{"config", options.config}, {"record", options.record}};
  Result<config::FusionConfig> config = config::load_fusion_config(options.config);
  if (!config) return report_failure(output, result, config.error().message);
  std::vector<std::unique_ptr<LiveSensor>> sensors;
  for (const config::SensorConfig& sensor : config->sensors) {
    if (!sensor.driver) continue;
    auto live = std::make_unique<LiveSensor>();
    live->sensor = &sensor;
    Result<drivers::SourceAddress> address = drivers::parse_source_url(sensor.driver->source);
    if (!address) return report_failure(output, result, fmt::format("sensor {}: {}", sensor.name, address.error().message));
    Result<std::unique_ptr<drivers::ByteSource>> source = drivers::open_source(*address);
    if (!source) return report_failure(output, result, fmt::format("sensor {}: {}", sensor.name, source.error().message));
    live->source = std::move(*source);
    Result<std::unique_ptr<LiveDecoder>> decoder = make_live_decoder(sensor);
    if (!decoder) return report_failure(output, result, decoder.error().message);
    live->decoder = std::move(*decoder);
    sensors.push_back(std::move(live));
  }
  if (sensors.empty()) {
    return report_failure(output, result, fmt::format("{}: no sensor has a driver (fusion.sensors.<name>.driver: type and source)", options.config));
  }
#ifdef HANZO_FUSION_WITH_SERVICE
  if (options.record.empty() && options.out.empty() && options.server.address.empty()) {
    return report_failure(output, result, "give --record LOG.mcap, --out DIR, --server HOST:PORT or several");
  }
  // Into a server session: the one named, or one made from this configuration.
  std::unique_ptr<service::FusionClient> client;
  std::unique_ptr<service::SessionStreams> uplink;
  if (!options.server.address.empty()) {
    Result<ServerSession> connected = connect_server_session(options.server, options.config, options.calibration, "drive " + options.config);
    if (!connected) return report_failure(output, result, connected.error().message);
    client = std::move(connected->client);
    result["session_id"] = connected->session_id;
    Result<std::unique_ptr<service::SessionStreams>> opened = client->open_streams(connected->session_id);
    if (!opened) return report_failure(output, result, opened.error().message);
    uplink = std::move(*opened);
  }
#else
  if (options.record.empty() && options.out.empty()) return report_failure(output, result, "give --record LOG.mcap, --out DIR or both");
#endif
  std::unique_ptr<pipeline::Session> session;
  std::vector<msgs::PoseEstimate> poses;
  if (!options.out.empty()) {
    calib::Calibration calibration;
    if (!options.calibration.empty()) {
      Result<calib::Calibration> loaded = calib::load_calibration(options.calibration);
      if (!loaded) return report_failure(output, result, loaded.error().message);
      calibration = std::move(*loaded);
    }
    pipeline::SessionConfig session_config = pipeline::SessionConfig::from(*config);
    session_config.mode = pipeline::SessionMode::kReplay;  // every message fused, in arrival order
    Result<std::unique_ptr<pipeline::Session>> created = pipeline::Session::create(*config, calibration, session_config);
    if (!created) return report_failure(output, result, created.error().message);
    session = std::move(*created);
    session->set_pose_callback([&poses](const msgs::PoseEstimate& pose) { poses.push_back(pose); });
    std::error_code error;
    std::filesystem::create_directories(options.out, error);
    if (error) return report_failure(output, result, fmt::format("{}: cannot create the output folder ({})", options.out, error.message()));
  }
  stop_requested = false;
  struct sigaction action{};
  action.sa_handler = request_stop;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
  std::atomic<bool> stop{false};
  std::vector<std::thread> readers;
  for (const std::unique_ptr<LiveSensor>& live : sensors) readers.emplace_back([&stop, raw = live.get()] { read_sensor(*raw, stop); });
  const auto started = std::chrono::steady_clock::now();
  uint64_t refused = 0;
  [[maybe_unused]] uint64_t server_errors = 0;
  // Until the duration passes or a signal comes: what the readers decoded goes to the log
  // (when recording) and the session, sensor by sensor.
  const auto consume = [&](io::SensorLogWriter* writer) -> Status {
    Status written = ok_status();
    const auto drain = [&] {
      for (const std::unique_ptr<LiveSensor>& live : sensors) {
        std::vector<msgs::SensorMessage> ready;
        {
          std::lock_guard lock(live->mutex);
          ready.swap(live->ready);
        }
        for (const msgs::SensorMessage& message : ready) {
          if (writer != nullptr) {
            if (Status status = writer->write(live->sensor->topic, message, live->sensor->name); !status && written) written = status;
          }
          if (session && !session->push(live->sensor->name, message)) ++refused;
#ifdef HANZO_FUSION_WITH_SERVICE
          if (uplink) {
            if (Status sent = uplink->send(live->sensor->name, message); !sent) {
              ++refused;
              if (server_errors++ == 0) logger()->error("drive: {}", sent.error().message);
            }
          }
#endif
        }
      }
    };
    while (!stop_requested && (options.duration <= 0.0 || std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() < options.duration)) {
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
      drain();
    }
    stop = true;
    for (std::thread& reader : readers) reader.join();
    readers.clear();
    drain();
    return written;
  };
  int code = 0;
  if (!options.record.empty()) {
    LogWriteOptions log;
    log.path = options.record;
    code = write_log(output, result, log, [&](io::SensorLogWriter& writer) -> Status {
      HANZO_RETURN_IF_ERROR(writer.add_metadata({"import", {{"importer", "drive"}, {"config", options.config}}}));
      return consume(&writer);
    });
  } else if (Status consumed = consume(nullptr); !consumed) {
    code = report_failure(output, result, consumed.error().message);
  }
  stop = true;
  for (std::thread& reader : readers) reader.join();
  if (code != 0) return code;
  if (session) {
    session->flush();
    const io::Trajectory trajectory = trajectory_of(poses);
    const std::string path = (std::filesystem::path(options.out) / "trajectory.tum").string();
    if (Status written = io::write_trajectory(path, trajectory, io::TrajectoryFormat::kTum); !written) return report_failure(output, result, written.error().message);
    result["poses"] = trajectory.size();
    result["refused_messages"] = refused;
    result["trajectory"] = path;
  }
#ifdef HANZO_FUSION_WITH_SERVICE
  if (uplink) {
    Result<service::StreamSummary> streamed = uplink->finish();
    if (!streamed) return report_failure(output, result, streamed.error().message);
    result["server"] = {{"messages_sent", streamed->messages_sent}, {"accepted", streamed->accepted}, {"poses_received", streamed->poses_received},
                        {"send_errors", server_errors}};
    if (streamed->messages_sent > 0 && streamed->accepted == 0) {
      return report_failure(output, result, fmt::format("session {} accepted none of the {} messages sent (GET /v1/sessions/{})",
                                                        result["session_id"].get<std::string>(), streamed->messages_sent,
                                                        result["session_id"].get<std::string>()));
    }
  }
#endif
  std::vector<std::string> without;
  nlohmann::json per_sensor = nlohmann::json::object();
  std::string text = fmt::format("{}: {:.1f} s{}\n", options.record.empty() ? options.out : options.record,
                                 std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count(),
                                 session ? fmt::format(", {} poses in {}", result["poses"].get<uint64_t>(), result["trajectory"].get<std::string>()) : "");
  for (const std::unique_ptr<LiveSensor>& live : sensors) {
    const LiveDecoderCounts counts = live->decoder->counts();
    per_sensor[live->sensor->name] = {{"source", live->source->address().url}, {"driver", live->sensor->driver->type}, {"topic", live->sensor->topic},
                                      {"reads", live->reads}, {"bytes", live->bytes}, {"messages", live->messages}, {"malformed", counts.malformed},
                                      {"silences", live->silences}, {"stream_error", live->stream_error}};
    text += fmt::format("  {} ({} from {}): {} messages on {} from {} reads, {} malformed{}{}\n", live->sensor->name, live->sensor->driver->type,
                        live->source->address().url, live->messages, live->sensor->topic, live->reads, counts.malformed,
                        live->silences > 0 ? fmt::format(", silent {} times", live->silences) : "",
                        live->stream_error.empty() ? "" : ", stream ended: " + live->stream_error);
    if (live->messages == 0) without.push_back(live->sensor->name);
  }
  result["sensors"] = per_sensor;
  if (!without.empty()) {
    return report_failure(output, result, fmt::format("{}: no messages from {} (the others' were kept)", options.record.empty() ? options.out : options.record,
                                                      fmt::join(without, ", ")));
  }
  result["ok"] = true;
  return report_success(output, result, text);
}

}  // namespace

void add_drive_command(CLI::App& app, const Output& output, Command& run) {
  auto options = std::make_shared<DriveOptions>();
  CLI::App* command = app.add_subcommand("drive", "Read the configured live sensors (drivers on UDP, TCP or serial sources) into a sensor log and / or a session");
  command->add_option("--config", options->config, "fusion.yaml whose sensors have a driver (type and source)")->required();
  command->add_option("--record", options->record, "Sensor log to write (.mcap)");
  command->add_option("--out", options->out, "Fuse the sensors in a session (as run does) and write its trajectory.tum here");
  command->add_option("--calib", options->calibration, "Sensor calibration YAML for --out (default: every sensor at the body origin)");
  command->add_option("--duration", options->duration, "Seconds to record (default: until Ctrl-C / SIGTERM)")->check(CLI::NonNegativeNumber);
#ifdef HANZO_FUSION_WITH_SERVICE
  add_server_options(*command, options->server, "Into a server session over gRPC (HOST:PORT): the one --session names, else a new one from --config and --calib");
#endif
  command->callback([&output, &run, options] { run = [&output, options] { return run_drive(output, *options); }; });
}

}  // namespace hanzo::fusion::app
