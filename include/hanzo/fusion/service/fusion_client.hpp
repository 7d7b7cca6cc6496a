#pragma once
// FusionClient: a client of a hanzo-fusion server (docs/server.md): sessions over REST, sensor
// data over gRPC. What `hanzo-fusion stream` runs.
//
//   auto client = FusionClient::create({.rest_url = "http://localhost:8083",
//                                       .grpc_address = "localhost:8084", .token = "..."}).value();
//   std::string id = client->create_session("yard run", config_yaml, calibration_yaml).value();
//   StreamSummary summary = client->stream_log("run.mcap", id, {.rate = 1.0}).value();
//
// stream_log() replays a sensor log (io/sensor_log.hpp) into a session: one gRPC stream per
// sensor (`Stream<Modality>` with metadata x-session-id and x-sensor), messages in log-time
// order. rate 1.0 keeps the log's timing (real time), 2.0 twice as fast; rate 0 streams as
// fast as the server fuses: a message is sent only when it is at most max_lead_s ahead of the
// newest PoseEstimate the server has sent back (the session time-orders within its lag window;
// a stream that ran further ahead would have its messages refused as too late).
// Topics map to the session's sensors through the session's own configuration (fetched over
// REST first), as `run` maps them: a log message is streamed when a configured sensor reads its
// topic, every other topic is skipped, counted and logged at warning level.
// Failure cases (returned Errors): the server unreachable or refusing (the error carries the
// URL or address tried, the server's status and message), an unreadable log, the server not
// answering for stall_timeout_s. A stream the session accepted no message of is not an error
// here: StreamSummary::accepted says so (`hanzo-fusion stream` exits 1 on it).
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"

namespace hanzo::fusion::service {

struct FusionClientConfig {
  std::string rest_url = "http://localhost:8083";  ///< http:// or https://
  std::string grpc_address = "localhost:8084";     ///< host:port
  std::string token;                               ///< API token ("" without auth)
  /// PEM CA bundle that signed the server's certificate: gRPC over TLS and HTTPS verification.
  /// Empty: plaintext gRPC (HTTPS with the system's CAs).
  std::string tls_ca_file;
};

struct StreamOptions {
  double rate = 1.0;         ///< x real time; 0 = as fast as the server fuses
  double max_lead_s = 0.25;  ///< rate 0: how far ahead of the server's newest pose to send
  double stall_timeout_s = 10.0;
  /// Log topic -> the session's sensor name; topics not listed are skipped. Empty (default):
  /// the topics of the session's configuration.
  std::map<std::string, std::string> sensor_by_topic;
};

struct StreamSummary {
  uint64_t messages_sent = 0;
  std::map<std::string, uint64_t> sent_by_sensor;
  std::map<std::string, uint64_t> skipped_by_topic;  ///< not streamed (pose estimates, topics no sensor reads)
  /// Messages the session took: its sensors' `received` counts less the input checks' rejections
  /// (unknown sensor, malformed, out of order, too late, ...), after minus before the stream.
  uint64_t accepted = 0;
  uint64_t poses_received = 0;                       ///< PoseEstimates the streams sent back
  std::optional<msgs::PoseEstimate> latest_pose;
  double log_seconds = 0.0;   ///< log time spanned
  double wall_seconds = 0.0;  ///< time the replay took
};

class FusionClient {
 public:
  static Result<std::unique_ptr<FusionClient>> create(const FusionClientConfig& config);
  ~FusionClient();
  FusionClient(const FusionClient&) = delete;
  FusionClient& operator=(const FusionClient&) = delete;

  /// POST /v1/sessions; returns the new session's id.
  Result<std::string> create_session(const std::string& name, const std::string& config_yaml, const std::string& calibration_yaml);
  /// GET of a REST path ("/v1/sessions/ID"): the body of a 2xx answer, else an Error with the
  /// server's status and message.
  Result<std::string> get(const std::string& path);
  /// DELETE /v1/sessions/{id}.
  Status end_session(const std::string& session_id);
  Result<StreamSummary> stream_log(const std::string& log_path, const std::string& session_id, const StreamOptions& options);

 private:
  struct Impl;
  explicit FusionClient(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace hanzo::fusion::service
