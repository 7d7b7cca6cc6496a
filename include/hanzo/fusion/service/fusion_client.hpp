#pragma once
// FusionClient: a client of a hanzo-fusion server (docs/server.md): sessions over REST, sensor
// data over gRPC. What `hanzo-fusion stream` runs.
//
//   auto client = FusionClient::create({.rest_url = "http://localhost:8083",
//                                       .grpc_address = "localhost:8084", .token = "..."}).value();
//   std::string id = client->create_session("yard run", config_yaml, calibration_yaml).value();
//   StreamSummary summary = client->stream_log("run.mcap", id, {.rate = 1.0}).value();
//
// stream_log() replays a sensor log (io/sensor_log.hpp) into a session through open_streams(): one gRPC stream per
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
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"

namespace hanzo::fusion::service {

struct FusionClientConfig {
  std::string rest_url = "http://localhost:8083";  ///< http:// or https://
  std::string grpc_address = "localhost:8084";     ///< host:port
  std::string token;                               ///< API token ("" without auth)
  /// PEM CA bundle that signed the server's certificate: gRPC over TLS and HTTPS verification.
  /// Empty: plaintext gRPC (HTTPS with the system's CAs).
  std::string tls_ca_file;
  /// A sensor stream the server ended with a transient status (UNAVAILABLE: its replica died or
  /// the session moved to another replica; a proxy's reset) is reopened with backoff (0.1 s
  /// doubling to 2 s) for up to this long without a pose coming back; 0: not retried. On
  /// reopening, the stream's messages of the last replay_s are sent again (a session restarted
  /// on another replica takes what it had not received; one that had them refuses them as out
  /// of order, counted in its session state).
  double reconnect_timeout_s = 30.0;
  double replay_s = 1.0;
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
  uint64_t reconnects = 0;    ///< streams reopened after the server ended them (reconnect_timeout_s)
  double log_seconds = 0.0;   ///< log time spanned
  double wall_seconds = 0.0;  ///< time the replay took
};

/// A session's sensor streams for messages the caller makes (live drivers: `hanzo-fusion drive
/// --server`), from FusionClient::open_streams: one gRPC stream per sensor, opened by its first
/// message, the poses the server sends back read on a thread per stream. Send from one thread.
/// The FusionClient must outlive it.
class SessionStreams {
 public:
  ~SessionStreams();
  SessionStreams(const SessionStreams&) = delete;
  SessionStreams& operator=(const SessionStreams&) = delete;

  /// Writes one message of the session's sensor `sensor`. A stream the server ended with a
  /// transient status is reopened (FusionClientConfig::reconnect_timeout_s). Fails when the
  /// server ended it for good (its status says why: an unknown session or sensor, a permission)
  /// or reopening did not bring a pose back in time; the stream is then closed and the next
  /// message of the sensor opens a new one.
  Status send(const std::string& sensor, const msgs::SensorMessage& message);
  /// The newest pose time the server has sent back on any stream; none before the first.
  std::optional<Timestamp> newest_pose_time() const;
  /// Closes every stream and waits for the server's status; the summary's `accepted` from the
  /// session's counts now against those at open_streams() (log_seconds and skipped_by_topic
  /// are the caller's to fill).
  Result<StreamSummary> finish();

 private:
  friend class FusionClient;
  struct State;
  explicit SessionStreams(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
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
  /// Streams into session_id for the caller's messages (GET of the session first: fails when
  /// the server or the session does not answer).
  Result<std::unique_ptr<SessionStreams>> open_streams(const std::string& session_id);

 private:
  friend class SessionStreams;
  struct Impl;
  explicit FusionClient(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace hanzo::fusion::service
