// hanzo-fusion serve: the server (REST on 8083, gRPC on 8084; docs/server.md). Runs until SIGINT/SIGTERM,
// then commits queued poses and exits 0. With --json it prints one JSON object on stdout once
// it listens ({"rest_port": ..., "grpc_port": ...}), so scripts and tests can use port 0.

#include <signal.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/service/allocator_tuning.hpp"
#include "hanzo/fusion/service/grpc_server.hpp"
#include "hanzo/fusion/service/jwt_verifier.hpp"
#include "hanzo/fusion/service/rest_server.hpp"
#include "hanzo/fusion/crypto/file_encryption.hpp"
#include "hanzo/fusion/object_store/object_store.hpp"
#include "hanzo/fusion/privacy/privacy_filter.hpp"
#include "hanzo/fusion/service/session_manager.hpp"

namespace hanzo::fusion::app {
namespace {

struct ServeOptions {
  std::string bind = "0.0.0.0";
  int port = 8083;
  int grpc_port = 8084;
  std::string data_dir = "hanzo-fusion-data";
  std::string database;
  std::string tokens_file;
  std::string jwks_file;
  service::JwtVerifierConfig jwt;
  bool insecure_no_auth = false;
  std::string tls_certificate;
  std::string tls_private_key;
  double max_body_mb = 16.0;
  std::size_t max_sessions = 256;
  std::size_t threads = 8;
  int map_save_interval_s = 30;
  std::size_t map_keep_versions = 20;
  bool record_sessions = false;
  std::string recording_privacy = "blur";
  bool allow_unfiltered_recordings = false;
  std::string encryption_key;
  std::string object_store;
  double recording_retention_days = 30.0;
  double recording_max_gb = 0.0;
  std::string replica_id;
  std::string replica_url;
  double lease_s = 10.0;
};

// The token store from --tokens, HANZO_FUSION_TOKENS_FILE or HANZO_FUSION_TOKENS, with the JWT
// verifier of --jwks; null with --insecure-no-auth.
Result<std::shared_ptr<const service::TokenStore>> load_tokens(const ServeOptions& options) {
  const char* file_variable = std::getenv("HANZO_FUSION_TOKENS_FILE");
  const char* inline_variable = std::getenv("HANZO_FUSION_TOKENS");
  const std::string file = !options.tokens_file.empty() ? options.tokens_file : (file_variable ? file_variable : "");
  if (options.insecure_no_auth) {
    if (!file.empty() || inline_variable != nullptr || !options.jwks_file.empty()) {
      return Error("--insecure-no-auth and API tokens or --jwks exclude each other");
    }
    return std::shared_ptr<const service::TokenStore>();
  }
  Result<service::TokenStore> store = service::TokenStore();
  if (!file.empty()) store = service::TokenStore::load(file);
  else if (inline_variable != nullptr) store = service::TokenStore::parse_inline(inline_variable);
  else if (options.jwks_file.empty()) {
    return Error("no API tokens: give --tokens FILE (or HANZO_FUSION_TOKENS_FILE / HANZO_FUSION_TOKENS) or --jwks FILE, or "
                 "--insecure-no-auth for local development");
  }
  if (!store) return store.error();
  if (!options.jwks_file.empty()) {
    Result<std::shared_ptr<const service::JwtVerifier>> verifier = service::JwtVerifier::open(options.jwks_file, options.jwt);
    if (!verifier) return verifier.error();
    store->set_jwt_verifier(*verifier);
  } else if (store->size() == 0) {
    return Error("the token file lists no tokens");
  }
  return std::shared_ptr<const service::TokenStore>(std::make_shared<service::TokenStore>(std::move(store).value()));
}

int run_serve(const Output& output, const ServeOptions& options) {
  // Signals are taken by sigwait below; block them before any thread starts.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGINT);
  sigaddset(&signals, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);
  if (!service::keep_large_buffers_on_heap()) logger()->debug("serve: the C library kept its own malloc thresholds");

  auto tokens = load_tokens(options);
  if (!tokens) return report_failure(output, {}, tokens.error().message);
  const std::string database =
      !options.database.empty() ? options.database : "sqlite://" + (std::filesystem::path(options.data_dir) / "fusion.db").string();
  auto storage = service::open_storage(database);
  if (!storage) return report_failure(output, {}, storage.error().message);
  auto metrics = std::make_shared<service::MetricsRegistry>();
  service::SessionManagerConfig manager_config;
  manager_config.max_sessions = options.max_sessions;
  manager_config.map_directory = (std::filesystem::path(options.data_dir) / "maps").string();
  manager_config.map_save_interval = std::chrono::seconds(options.map_save_interval_s);
  manager_config.map_keep_versions = options.map_keep_versions;
  service::RecordingConfig& recording = manager_config.recording;
  recording.directory = (std::filesystem::path(options.data_dir) / "recordings").string();
  recording.record_by_default = options.record_sessions;
  auto redaction = privacy::parse_redaction(options.recording_privacy);
  if (!redaction) return report_failure(output, {}, "--recording-privacy: " + redaction.error().message);
  recording.redaction = *redaction;
  recording.allow_unfiltered = options.allow_unfiltered_recordings;
  if (!options.encryption_key.empty()) {
    auto key = crypto::EncryptionKey::load(options.encryption_key);
    if (!key) return report_failure(output, {}, "--encryption-key: " + key.error().message);
    recording.key = *key;
    manager_config.map_store.encryption_key = *key;
  }
  // Maps stored before a key rotation name their key: the keys of $HANZO_ENCRYPTION_KEY decrypt too.
  auto old_keys = crypto::keys_from_environment();
  if (!old_keys) return report_failure(output, {}, "HANZO_ENCRYPTION_KEY: " + old_keys.error().message);
  manager_config.map_store.decryption_keys = std::move(*old_keys);
  if (!options.object_store.empty()) {
    auto objects = object_store::open_object_store(options.object_store);
    if (!objects) return report_failure(output, {}, "--object-store: " + objects.error().message);
    // One listing now, so that an unreachable store, a missing bucket or refused credentials
    // stop the start with the reason instead of failing the first save.
    if (auto probe = (*objects)->list(".hanzo-fusion-probe/"); !probe) return report_failure(output, {}, "--object-store: " + probe.error().message);
    manager_config.object_store = std::move(*objects);
  }
  std::string replica_secret;
  if (!options.replica_id.empty()) {
    std::string url = options.replica_url;
    if (url.empty()) {
      if (options.port == 0) return report_failure(output, {}, "--replica-url: needed with --port 0 (the other replicas forward requests there)");
      const std::string host = options.bind == "0.0.0.0" || options.bind == "::" ? "127.0.0.1" : options.bind;
      url = fmt::format("{}://{}:{}", options.tls_certificate.empty() ? "http" : "https", host, options.port);
    }
    manager_config.replica = {options.replica_id, url, std::chrono::milliseconds(std::llround(options.lease_s * 1000.0)), nullptr};
    const char* secret = std::getenv("HANZO_FUSION_REPLICA_SECRET");
    if (secret == nullptr || std::string_view(secret).size() < 16) {
      return report_failure(output, {}, "--replica-id: set HANZO_FUSION_REPLICA_SECRET (16 characters or more, the same on every replica)");
    }
    replica_secret = secret;
    manager_config.replica.request_handover = service::replica_handover_requester(replica_secret, options.replica_id, url);
  } else if (!options.replica_url.empty()) {
    return report_failure(output, {}, "--replica-url: applies to a replica; set --replica-id too");
  }
  recording.retention = std::chrono::hours(static_cast<int64_t>(std::lround(options.recording_retention_days * 24.0)));
  recording.max_total_bytes = static_cast<uint64_t>(options.recording_max_gb * 1e9);
  auto sessions = service::SessionManager::create(manager_config, std::move(storage).value(), metrics);
  if (!sessions) return report_failure(output, {}, sessions.error().message);

  service::RestServerConfig rest_config;
  rest_config.bind_address = options.bind;
  rest_config.port = options.port;
  rest_config.tls_certificate = options.tls_certificate;
  rest_config.tls_private_key = options.tls_private_key;
  rest_config.max_body_bytes = static_cast<std::size_t>(options.max_body_mb * 1024 * 1024);
  rest_config.threads = options.threads;
  rest_config.replica_secret = replica_secret;
  auto rest = service::RestServer::create(rest_config, *sessions.value(), tokens.value(), metrics);
  if (!rest) return report_failure(output, {}, rest.error().message);
  if (Status started = rest.value()->start(); !started) return report_failure(output, {}, started.error().message);

  service::GrpcServerConfig grpc_config;
  grpc_config.bind_address = options.bind;
  grpc_config.port = options.grpc_port;
  grpc_config.tls_certificate = options.tls_certificate;
  grpc_config.tls_private_key = options.tls_private_key;
  auto grpc = service::GrpcServer::create(grpc_config, *sessions.value(), tokens.value(), metrics);
  if (!grpc) return report_failure(output, {}, grpc.error().message);
  if (Status started = grpc.value()->start(); !started) return report_failure(output, {}, started.error().message);

  const bool auth = tokens.value() != nullptr;
  if (!auth) std::cerr << "hanzo-fusion serve: WARNING: authentication is OFF (--insecure-no-auth); every request has every permission\n";
  const std::string scheme = rest.value()->https() ? "https" : "http";
  nlohmann::json ready = {{"rest_port", rest.value()->port()}, {"grpc_port", grpc.value()->port()}, {"rest_url", fmt::format("{}://{}:{}", scheme, options.bind, rest.value()->port())},
                          {"storage", std::string(sessions.value()->storage_backend())}, {"auth", auth},
                          {"active_sessions", sessions.value()->active_sessions()},
                          {"replica", options.replica_id.empty() ? nlohmann::json(nullptr) : nlohmann::json(options.replica_id)}};
  if (output.json) {
    std::cout << ready.dump() << std::endl;
  } else {
    std::cerr << fmt::format("hanzo-fusion serve: REST on {}, gRPC on {}:{} ({} storage, auth {}, {} sessions restored); Ctrl-C stops\n",
                             ready["rest_url"].get<std::string>(), options.bind, grpc.value()->port(),
                             ready["storage"].get<std::string>(), auth ? "on" : "OFF",
                             sessions.value()->active_sessions());
  }

  int signal_number = 0;
  sigwait(&signals, &signal_number);
  std::cerr << "hanzo-fusion serve: stopping (" << (signal_number == SIGINT ? "SIGINT" : "SIGTERM") << ")\n";
  rest.value()->stop();
  grpc.value()->stop();
  if (Status flushed = sessions.value()->flush_storage(); !flushed) {
    std::cerr << "hanzo-fusion serve: " << flushed.error().message << "\n";
    return 1;
  }
  return 0;
}

}  // namespace

void add_serve_command(CLI::App& app, const Output& output, Command& run) {
  auto options = std::make_shared<ServeOptions>();
  CLI::App* command = app.add_subcommand("serve", "Run the server: REST API on --port (8083), gRPC streaming on --grpc-port (8084)");
  command->add_option("--bind", options->bind, "Address to listen on")->capture_default_str();
  command->add_option("--port", options->port, "REST port (0: any free port)")->capture_default_str()->check(CLI::Range(0, 65535));
  command->add_option("--grpc-port", options->grpc_port, "gRPC streaming port (0: any free port)")->capture_default_str()->check(CLI::Range(0, 65535));
  command->add_option("--data-dir", options->data_dir, "Folder of the SQLite database and of the stored maps (DATA_DIR/maps)")->capture_default_str();
  command->add_option("--map-save-interval", options->map_save_interval_s,
                      "Seconds between saves of a changed session map as a new version (0: only when the session ends)")
      ->capture_default_str()->check(CLI::Range(0, 86400));
  command->add_option("--map-keep-versions", options->map_keep_versions,
                      "Newest versions kept of each session's map; older autosaves are deleted (0: keep all; loaded maps are never pruned)")
      ->capture_default_str();
  command->add_flag("--record-sessions", options->record_sessions,
                    "Record every session's raw sensor streams into DATA_DIR/recordings (a session may say \"record\": false; without "
                    "this flag sessions record when they ask)");
  command->add_option("--recording-privacy", options->recording_privacy, "Faces and licence plates in recorded images: blur or black")
      ->capture_default_str();
  command->add_flag("--allow-unfiltered-recordings", options->allow_unfiltered_recordings,
                    "Let a session record its images unfiltered (\"privacy\": \"off\")");
  command->add_option("--encryption-key", options->encryption_key,
                      "Key file: finished recordings and stored map versions are encrypted at rest (docs/security.md)")
      ->check(CLI::ExistingFile);
  command->add_option("--object-store", options->object_store,
                      "s3://BUCKET/PREFIX[?endpoint=URL&region=R]: maps and finished recordings are kept there instead of DATA_DIR "
                      "(credentials from AWS_ACCESS_KEY_ID / AWS_SECRET_ACCESS_KEY; docs/security.md)");
  command->add_option("--recording-retention-days", options->recording_retention_days, "Finished recordings older than this are deleted (0: kept)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  command->add_option("--recording-max-gb", options->recording_max_gb, "Beyond this size of finished recordings the oldest are deleted (0: no cap)")
      ->capture_default_str()->check(CLI::NonNegativeNumber);
  command->add_option("--replica-id", options->replica_id,
                      "Run as one of several replicas on one --db and --object-store, this one named so (docs/server.md \"Replicas\")");
  command->add_option("--replica-url", options->replica_url,
                      "Where the other replicas reach this one's REST API (default http://BIND:PORT, 127.0.0.1 for 0.0.0.0)");
  command->add_option("--lease-s", options->lease_s, "Replicas: a session lease's length; a dead replica's sessions are taken over after it")
      ->capture_default_str()->check(CLI::Range(0.5, 3600.0));
  command->add_option("--db", options->database, "Storage URL: sqlite://PATH or postgresql://USER@HOST:PORT/DB (default sqlite://DATA_DIR/fusion.db)");
  command->add_option("--tokens", options->tokens_file, "API token file (YAML; docs/server.md)");
  command->add_option("--jwks", options->jwks_file, "JWKS file or http(s) URL of an OIDC provider: bearer JWTs (RS256 / ES256) are accepted (docs/security.md)");
  command->add_option("--jwt-issuer", options->jwt.issuer, "The JWTs' required issuer (\"iss\"), with --jwks");
  command->add_option("--jwt-audience", options->jwt.audience, "The JWTs' required audience (\"aud\"), with --jwks");
  command->add_option("--jwt-organization-claim", options->jwt.organization_claim, "Claim naming the organization")->capture_default_str();
  command->add_option("--jwt-scope-claim", options->jwt.scope_claim, "Claim listing the fusion:* scopes")->capture_default_str();
  command->add_flag("--insecure-no-auth", options->insecure_no_auth, "Serve without authentication (local development only)");
  command->add_option("--tls-cert", options->tls_certificate, "PEM certificate: serve HTTPS (with --tls-key)")->check(CLI::ExistingFile);
  command->add_option("--tls-key", options->tls_private_key, "PEM private key of --tls-cert")->check(CLI::ExistingFile);
  command->add_option("--max-body-mb", options->max_body_mb, "Largest request body accepted (MiB)")->capture_default_str()->check(CLI::Range(0.001, 4096.0));
  command->add_option("--max-sessions", options->max_sessions, "Most sessions running at once")->capture_default_str()->check(CLI::Range(1, 100000));
  command->add_option("--threads", options->threads, "REST request workers")->capture_default_str()->check(CLI::Range(1, 1024));
  command->callback([&run, &output, options] { run = [&output, options] { return run_serve(output, *options); }; });
}

}  // namespace hanzo::fusion::app
