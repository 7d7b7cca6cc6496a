#include "server_session.hpp"

#include <cstdlib>

#include <fmt/format.h>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"

namespace hanzo::fusion::app {

void add_server_options(CLI::App& command, ServerOptions& options, const std::string& server_help) {
  CLI::Option* server = command.add_option("--server", options.address, server_help);
  if (!options.address.empty()) server->capture_default_str();
  command.add_option("--rest", options.rest_url, "REST URL (default http://HOST:8083, https with --tls-ca)");
  command.add_option("--session", options.session_id, "An existing session to send into (default: one is created)");
  command.add_option("--name", options.name, "Name of the session created");
  command.add_option("--token", options.token, "API token (default: $HANZO_FUSION_TOKEN)");
  command.add_option("--tls-ca", options.tls_ca_file, "PEM CA certificate of a TLS server")->check(CLI::ExistingFile);
}

Result<ServerSession> connect_server_session(const ServerOptions& options, const std::string& config_path, const std::string& calibration_path,
                                             const std::string& default_name) {
  service::FusionClientConfig client_config;
  client_config.grpc_address = options.address;
  const std::string host = options.address.substr(0, options.address.rfind(':'));
  client_config.rest_url = !options.rest_url.empty() ? options.rest_url
                                                     : fmt::format("{}://{}:8083", options.tls_ca_file.empty() ? "http" : "https", host);
  const char* token_variable = std::getenv("HANZO_FUSION_TOKEN");
  client_config.token = !options.token.empty() ? options.token : (token_variable ? token_variable : "");
  client_config.tls_ca_file = options.tls_ca_file;
  std::string config_yaml, calibration_yaml;
  if (options.session_id.empty()) {
    if (config_path.empty()) return Error("give --config (and --calib) to create a session, or --session ID to send into an existing one");
    Result<config::FusionConfig> configuration = config::load_fusion_config(config_path);
    if (!configuration) return configuration.error();
    config_yaml = config::to_yaml(*configuration);
    if (!calibration_path.empty()) {
      Result<calib::Calibration> calibration = calib::load_calibration(calibration_path);
      if (!calibration) return calibration.error();
      calibration_yaml = calib::to_yaml(*calibration);
    }
  }
  ServerSession session;
  HANZO_ASSIGN_OR_RETURN(session.client, service::FusionClient::create(client_config));
  session.session_id = options.session_id;
  if (session.session_id.empty()) {
    HANZO_ASSIGN_OR_RETURN(session.session_id, session.client->create_session(options.name.empty() ? default_name : options.name, config_yaml, calibration_yaml));
  }
  return session;
}

}  // namespace hanzo::fusion::app
