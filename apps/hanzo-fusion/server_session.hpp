#pragma once
// A server session for the commands that send sensor data over gRPC (stream, drive --server):
// the options that reach it (--server, --rest, --session, --name, --token, --tls-ca) and the
// connection: the session --session names, else a new one from a configuration and calibration
// file (POST /v1/sessions). Built with the service module only.

#include <memory>
#include <string>

#include <CLI/CLI.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/service/fusion_client.hpp"

namespace hanzo::fusion::app {

struct ServerOptions {
  std::string address;      ///< gRPC HOST:PORT ("" where the command makes it optional: no server)
  std::string rest_url;     ///< default http://HOST:8083 (https with tls_ca_file)
  std::string session_id;   ///< an existing session to send into; "": one is created
  std::string name;         ///< of the session created
  std::string token;        ///< default $HANZO_FUSION_TOKEN
  std::string tls_ca_file;
};

/// Adds --server (described by server_help; its value is shown as default when set), --rest,
/// --session, --name, --token and --tls-ca.
void add_server_options(CLI::App& command, ServerOptions& options, const std::string& server_help);

struct ServerSession {
  std::unique_ptr<service::FusionClient> client;
  std::string session_id;
};

/// The client and the session: --session's, else one created from config_path (required then)
/// and calibration_path (optional), named options.name or default_name.
Result<ServerSession> connect_server_session(const ServerOptions& options, const std::string& config_path, const std::string& calibration_path,
                                             const std::string& default_name);

}  // namespace hanzo::fusion::app
