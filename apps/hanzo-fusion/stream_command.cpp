// hanzo-fusion stream LOG --server HOST:PORT: replays a sensor log into a server session over
// gRPC (docs/server.md, "Stream a log"). Creates the session from --config/--calib over REST
// unless --session names one; the session's configuration maps the log's topics to its sensors.
// Prints what was sent and the session's state at the end; exits 1 when the session accepted
// none of the messages.

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "hanzo/fusion/service/fusion_client.hpp"
#include "server_session.hpp"

namespace hanzo::fusion::app {
namespace {

struct StreamCommandOptions {
  std::string log_path;
  std::string config_path;
  std::string calibration_path;
  ServerOptions server = [] {
    ServerOptions defaults;
    defaults.address = "localhost:8084";
    return defaults;
  }();
  std::string rate = "1.0";
  bool end = false;
};

int run_stream(const Output& output, const StreamCommandOptions& options) {
  nlohmann::json result = {{"log", options.log_path}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  service::StreamOptions stream_options;
  if (options.rate == "max") {
    stream_options.rate = 0.0;
  } else {
    try {
      std::size_t used = 0;
      stream_options.rate = std::stod(options.rate, &used);
      if (used != options.rate.size() || !(stream_options.rate > 0)) throw std::invalid_argument("rate");
    } catch (const std::exception&) {
      return fail(fmt::format("--rate '{}': expected a positive number or 'max'", options.rate));
    }
  }
  Result<ServerSession> connected = connect_server_session(options.server, options.config_path, options.calibration_path, options.log_path);
  if (!connected) return fail(connected.error().message);
  service::FusionClient* client = connected->client.get();
  const std::string& session_id = connected->session_id;
  result["session_id"] = session_id;
  auto streamed = client->stream_log(options.log_path, session_id, stream_options);
  if (!streamed) return fail(streamed.error().message);
  const service::StreamSummary& summary = streamed.value();
  result["messages_sent"] = summary.messages_sent;
  result["sent_by_sensor"] = summary.sent_by_sensor;
  result["skipped_by_topic"] = summary.skipped_by_topic;
  result["accepted"] = summary.accepted;
  result["poses_received"] = summary.poses_received;
  result["reconnects"] = summary.reconnects;
  result["log_seconds"] = summary.log_seconds;
  result["wall_seconds"] = summary.wall_seconds;
  auto state = client->get("/v1/sessions/" + session_id);
  if (!state) return fail(state.error().message);
  result["session"] = nlohmann::json::parse(state.value(), nullptr, false);
  if (summary.accepted == 0) {
    std::string skipped;
    for (const auto& [topic, count] : summary.skipped_by_topic) skipped += fmt::format("{}{}", skipped.empty() ? "" : ", ", topic);
    return fail(summary.messages_sent == 0
                    ? fmt::format("no topic of the log is read by a sensor of session {} (log topics: {})", session_id, skipped)
                    : fmt::format("session {} accepted none of the {} messages sent (see its sensors' rejections: GET /v1/sessions/{})",
                                  session_id, summary.messages_sent, session_id));
  }
  if (options.end) {
    if (Status ended = client->end_session(session_id); !ended) return fail(ended.error().message);
    result["ended"] = true;
  }
  std::string text = fmt::format("session {}: {} messages streamed ({:.1f} s of log in {:.1f} s), {} accepted, {} poses back", session_id,
                                 summary.messages_sent, summary.log_seconds, summary.wall_seconds, summary.accepted, summary.poses_received);
  for (const auto& [sensor, count] : summary.sent_by_sensor) text += fmt::format("\n  {}: {}", sensor, count);
  for (const auto& [topic, count] : summary.skipped_by_topic) text += fmt::format("\n  skipped {}: {} (no sensor reads it)", topic, count);
  const nlohmann::json& session = result["session"];
  if (session.is_object() && session.contains("mapping")) {
    const nlohmann::json& mapping = session["mapping"];
    text += fmt::format("\nserver: state {}, {} poses stored; LiDAR {} of {} sweeps registered, {} map keyframes, {} loop closures",
                        session.value("tracking_state", "?"), session.value("stored_poses", 0), mapping.value("scans_registered", 0),
                        mapping.value("scans_received", 0), mapping.value("map_keyframes", 0), mapping.value("loop_closures", 0));
  }
  return report_success(output, result, text + "\n");
}

}  // namespace

void add_stream_command(CLI::App& app, const Output& output, Command& run) {
  auto options = std::make_shared<StreamCommandOptions>();
  CLI::App* command = app.add_subcommand("stream", "Replay a sensor log into a server session over gRPC");
  command->add_option("log", options->log_path, "Sensor log (.mcap)")->required()->check(CLI::ExistingFile);
  add_server_options(*command, options->server, "gRPC address HOST:PORT");
  command->add_option("--config", options->config_path, "Fusion configuration: creates the session (its topics map the log)")->check(CLI::ExistingFile);
  command->add_option("--calibration,--calib", options->calibration_path, "Calibration of the session created")->check(CLI::ExistingFile);
  command->add_option("--rate", options->rate, "Replay speed: 1.0 real time, 2.0 twice as fast, max as fast as the server fuses")->capture_default_str();
  command->add_flag("--end", options->end, "End the session when the log is done");
  command->callback([&run, &output, options] { run = [&output, options] { return run_stream(output, *options); }; });
}

}  // namespace hanzo::fusion::app
