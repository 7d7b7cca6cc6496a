// hanzo-fusion stream LOG --server HOST:PORT: replays a sensor log into a server session over
// gRPC (docs/server.md, "Stream a log"). Creates the session from --config/--calib over REST
// unless --session names one; the session's configuration maps the log's topics to its sensors.
// Prints what was sent and the session's state at the end; exits 1 when the session accepted
// none of the messages.

#include <cstdlib>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/service/fusion_client.hpp"

namespace hanzo::fusion::app {
namespace {

struct StreamCommandOptions {
  std::string log_path;
  std::string grpc_address = "localhost:8084";
  std::string rest_url;
  std::string config_path;
  std::string calibration_path;
  std::string session_id;
  std::string name;
  std::string token;
  std::string rate = "1.0";
  std::string tls_ca_file;
  bool end = false;
};

int run_stream(const Output& output, const StreamCommandOptions& options) {
  nlohmann::json result = {{"log", options.log_path}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  service::FusionClientConfig client_config;
  client_config.grpc_address = options.grpc_address;
  const std::string host = options.grpc_address.substr(0, options.grpc_address.rfind(':'));
  client_config.rest_url = !options.rest_url.empty() ? options.rest_url
                                                     : fmt::format("{}://{}:8083", options.tls_ca_file.empty() ? "http" : "https", host);
  const char* token_variable = std::getenv("HANZO_FUSION_TOKEN");
  client_config.token = !options.token.empty() ? options.token : (token_variable ? token_variable : "");
  client_config.tls_ca_file = options.tls_ca_file;

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
  std::string config_yaml, calibration_yaml;
  if (!options.config_path.empty()) {
    auto configuration = config::load_fusion_config(options.config_path);
    if (!configuration) return fail(configuration.error().message);
    config_yaml = config::to_yaml(*configuration);
    if (!options.calibration_path.empty()) {
      auto calibration = calib::load_calibration(options.calibration_path);
      if (!calibration) return fail(calibration.error().message);
      calibration_yaml = calib::to_yaml(*calibration);
    }
  } else if (options.session_id.empty()) {
    return fail("give --config (and --calib) to create a session, or --session ID to stream into an existing one");
  }

  auto client = service::FusionClient::create(client_config);
  if (!client) return fail(client.error().message);
  std::string session_id = options.session_id;
  if (session_id.empty()) {
    auto created = client.value()->create_session(options.name.empty() ? options.log_path : options.name, config_yaml, calibration_yaml);
    if (!created) return fail(created.error().message);
    session_id = created.value();
  }
  result["session_id"] = session_id;
  auto streamed = client.value()->stream_log(options.log_path, session_id, stream_options);
  if (!streamed) return fail(streamed.error().message);
  const service::StreamSummary& summary = streamed.value();
  result["messages_sent"] = summary.messages_sent;
  result["sent_by_sensor"] = summary.sent_by_sensor;
  result["skipped_by_topic"] = summary.skipped_by_topic;
  result["accepted"] = summary.accepted;
  result["poses_received"] = summary.poses_received;
  result["log_seconds"] = summary.log_seconds;
  result["wall_seconds"] = summary.wall_seconds;
  auto state = client.value()->get("/v1/sessions/" + session_id);
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
    if (Status ended = client.value()->end_session(session_id); !ended) return fail(ended.error().message);
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
  command->add_option("--server", options->grpc_address, "gRPC address HOST:PORT")->capture_default_str();
  command->add_option("--rest", options->rest_url, "REST URL (default http://HOST:8083, https with --tls-ca)");
  command->add_option("--config", options->config_path, "Fusion configuration: creates the session (its topics map the log)")->check(CLI::ExistingFile);
  command->add_option("--calibration,--calib", options->calibration_path, "Calibration of the session created")->check(CLI::ExistingFile);
  command->add_option("--session", options->session_id, "Stream into this existing session instead");
  command->add_option("--name", options->name, "Name of the session created (default: the log's path)");
  command->add_option("--token", options->token, "API token (default: $HANZO_FUSION_TOKEN)");
  command->add_option("--rate", options->rate, "Replay speed: 1.0 real time, 2.0 twice as fast, max as fast as the server fuses")->capture_default_str();
  command->add_option("--tls-ca", options->tls_ca_file, "PEM CA certificate of a TLS server")->check(CLI::ExistingFile);
  command->add_flag("--end", options->end, "End the session when the log is done");
  command->callback([&run, &output, options] { run = [&output, options] { return run_stream(output, *options); }; });
}

}  // namespace hanzo::fusion::app
