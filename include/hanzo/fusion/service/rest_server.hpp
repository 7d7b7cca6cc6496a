#pragma once
// The REST API (spec "REST API (Port 8083)"; every route in docs/openapi.json, served at
// /v1/openapi.json). JSON in and out; every error is
//   {"error": {"code": "not_found", "message": "no session 'abc'", "field": "session_id"}}
// with the HTTP status of its code (api_error.hpp). Requests carry
// "Authorization: Bearer TOKEN" (auth.hpp) except GET /v1/health and GET /v1/openapi.json;
// /v1/metrics needs fusion:admin.
//
// HTTPS when tls_certificate and tls_private_key are given (PEM files). Bodies above
// max_body_bytes are refused with 413 before they are read in full.

#include <cstddef>
#include <functional>
#include <memory>
#include <string>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/service/auth.hpp"
#include "hanzo/fusion/service/metrics.hpp"
#include "hanzo/fusion/service/session_manager.hpp"

namespace hanzo::fusion::service {

struct RestServerConfig {
  std::string bind_address = "0.0.0.0";
  int port = 8083;                      // 0 picks a free port (tests)
  std::string tls_certificate;          // PEM; with tls_private_key turns on HTTPS
  std::string tls_private_key;
  std::size_t max_body_bytes = 16u << 20;  // 16 MiB
  std::size_t threads = 8;              // request workers
  /// Replicas: the secret they share. POST /v1/replica/sessions/{id}/handover (another replica
  /// asking this one to hand a session over) is answered only with it (header
  /// X-Hanzo-Replica-Secret); empty: the route answers 404.
  std::string replica_secret;
};

class RestServer {
 public:
  /// `tokens` null turns authentication off (--insecure-no-auth): every request acts as
  /// Principal::local_development(). Fails when the TLS files cannot be loaded.
  static Result<std::unique_ptr<RestServer>> create(const RestServerConfig& config, SessionManager& sessions,
                                                    std::shared_ptr<const TokenStore> tokens,
                                                    std::shared_ptr<MetricsRegistry> metrics);
  ~RestServer();  // stops
  RestServer(const RestServer&) = delete;
  RestServer& operator=(const RestServer&) = delete;

  /// Binds and serves on a background thread; fails naming the address when the port is taken.
  Status start();
  /// The bound port (after start()).
  int port() const;
  bool https() const;
  void stop();

 private:
  struct Impl;
  explicit RestServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

/// ReplicaConfig::request_handover over REST for the replica `replica_id` (at `replica_url`):
/// POST {owner_url}/v1/replica/sessions/{id}/handover {"replica", "url"} with the replicas'
/// shared secret; fails naming the replica and its answer.
std::function<Status(const SessionLease& lease)> replica_handover_requester(std::string secret, std::string replica_id, std::string replica_url);

/// The OpenAPI 3 document of the REST API (docs/openapi.json, compiled in).
std::string_view openapi_document();

}  // namespace hanzo::fusion::service
