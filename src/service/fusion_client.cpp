#include "hanzo/fusion/service/fusion_client.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <deque>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>
#include <type_traits>
#include <vector>

#include <fmt/format.h>
#include <grpcpp/grpcpp.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/pipeline/rejection.hpp"
#include "hanzo/fusion/msgs/convert.hpp"
#include "hanzo/fusion/v1/service.grpc.pb.h"
// Last: httplib pulls in <resolv.h>, whose `_res` macro breaks Eigen headers included after it.
#include <httplib.h>

namespace hanzo::fusion::service {
namespace {

using Clock = std::chrono::steady_clock;
using nlohmann::json;

// The server's error of a REST answer: "HTTP 404 not_found: no session 'x'"; without an answer
// the URL tried and why.
Error http_error(const httplib::Result& response, const std::string& what, const std::string& url) {
  if (!response) {
    // httplib names only the step that failed ("Connection"): say what it means.
    std::string reason;
    switch (response.error()) {
      case httplib::Error::Connection: reason = "cannot connect: is the server running and listening there?"; break;
      case httplib::Error::ConnectionTimeout: reason = "the connection timed out"; break;
      case httplib::Error::Read: reason = "the server closed the connection or sent nothing"; break;
      case httplib::Error::Write: reason = "the request could not be sent"; break;
      case httplib::Error::SSLConnection: reason = "the TLS handshake failed (is it an https server?)"; break;
      case httplib::Error::SSLServerVerification: reason = "the server's TLS certificate was not verified"; break;
      default: reason = httplib::to_string(response.error()); break;
    }
    return Error(fmt::format("{}: {} ({})", what, reason, url));
  }
  std::string message = response->body;
  try {
    const json body = json::parse(response->body);
    message = fmt::format("{}: {}", body["error"].value("code", ""), body["error"].value("message", ""));
  } catch (const std::exception&) {
  }
  return Error(fmt::format("{}: HTTP {} {}", what, response->status, message));
}

// One gRPC sensor stream (one sensor of the session): writes messages, reads the poses the
// server sends back on a thread of its own.
class SensorStream {
 public:
  virtual ~SensorStream() = default;
  /// False when the stream broke (the server ended it).
  virtual bool write(const msgs::SensorMessage& message) = 0;
  /// Half-closes, waits for the server's status.
  virtual grpc::Status finish() = 0;
};

struct PoseProgress {
  std::atomic<int64_t> newest_ns{INT64_MIN};
  std::atomic<uint64_t> received{0};
  std::mutex mutex;
  std::optional<msgs::PoseEstimate> latest;

  void record(const v1::PoseEstimate& proto) {
    received.fetch_add(1);
    auto pose = msgs::from_proto(proto);
    if (!pose) return;
    const int64_t time = pose->timestamp.nanoseconds();
    int64_t seen = newest_ns.load();
    while (time > seen && !newest_ns.compare_exchange_weak(seen, time)) {
    }
    std::lock_guard lock(mutex);
    if (!latest || latest->timestamp < pose->timestamp) latest = std::move(pose).value();
  }
};

template <typename Message, typename RequestProto>
class TypedSensorStream final : public SensorStream {
 public:
  template <typename Open>
  TypedSensorStream(Open open, const std::string& token, const std::string& session_id, const std::string& sensor, PoseProgress& progress) {
    if (!token.empty()) context_.AddMetadata("authorization", "Bearer " + token);
    context_.AddMetadata("x-session-id", session_id);
    context_.AddMetadata("x-sensor", sensor);
    stream_ = open(&context_);
    reader_ = std::thread([this, &progress] {
      v1::PoseEstimate pose;
      while (stream_->Read(&pose)) progress.record(pose);
    });
  }
  ~TypedSensorStream() override {
    if (reader_.joinable()) {
      context_.TryCancel();
      reader_.join();
    }
  }
  bool write(const msgs::SensorMessage& message) override {
    const auto* typed = std::get_if<Message>(&message);
    if (typed == nullptr) return false;
    if constexpr (std::is_same_v<Message, msgs::PointCloudMessage>) {
      msgs::to_proto(*typed, &sweep_, msgs::PointEncoding::kPacked);  // reuses the previous sweep's storage
      return stream_->Write(sweep_);
    } else {
      return stream_->Write(msgs::to_proto(*typed));
    }
  }
  grpc::Status finish() override {
    stream_->WritesDone();
    reader_.join();
    return stream_->Finish();
  }

 private:
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReaderWriter<RequestProto, v1::PoseEstimate>> stream_;
  std::thread reader_;
  v1::PointCloudMessage sweep_;  // point cloud streams: the message written, reused
};

// Messages a session took so far (GET /v1/sessions/ID answer): its sensors' received counts
// less the rejections by input checks.
uint64_t accepted_messages(const json& session) {
  uint64_t accepted = 0;
  const json sensors = session.value("sensors", json::array());
  for (const json& sensor : sensors) {
    uint64_t refused = 0;
    const json rejected = sensor.value("rejected", json::object());
    for (const auto& [reason, count] : rejected.items()) {
      const std::optional<pipeline::Rejection> rejection = pipeline::rejection_from_string(reason);
      if (rejection && pipeline::is_input_check(*rejection)) refused += count.get<uint64_t>();
    }
    accepted += sensor.value("received", uint64_t{0}) - std::min(refused, sensor.value("received", uint64_t{0}));
  }
  return accepted;
}

}  // namespace

struct FusionClient::Impl {
  FusionClientConfig config;
  std::unique_ptr<httplib::Client> http;
  std::unique_ptr<v1::FusionService::Stub> stub;

  httplib::Headers headers() const {
    if (config.token.empty()) return {};
    return {{"Authorization", "Bearer " + config.token}};
  }

  std::unique_ptr<SensorStream> open_stream(const msgs::SensorMessage& kind, const std::string& session_id, const std::string& sensor,
                                            PoseProgress& progress) {
    v1::FusionService::Stub& s = *stub;
    const std::string& token = config.token;
    switch (kind.index()) {
      case 0: return std::make_unique<TypedSensorStream<msgs::ImuMessage, v1::ImuMessage>>([&](grpc::ClientContext* c) { return s.StreamImu(c); }, token, session_id, sensor, progress);
      case 1: return std::make_unique<TypedSensorStream<msgs::PointCloudMessage, v1::PointCloudMessage>>([&](grpc::ClientContext* c) { return s.StreamPointCloud(c); }, token, session_id, sensor, progress);
      case 2: return std::make_unique<TypedSensorStream<msgs::ImageMessage, v1::ImageMessage>>([&](grpc::ClientContext* c) { return s.StreamImage(c); }, token, session_id, sensor, progress);
      case 3: return std::make_unique<TypedSensorStream<msgs::GnssMessage, v1::GnssMessage>>([&](grpc::ClientContext* c) { return s.StreamGnss(c); }, token, session_id, sensor, progress);
      case 4: return std::make_unique<TypedSensorStream<msgs::WheelOdometryMessage, v1::WheelOdometryMessage>>([&](grpc::ClientContext* c) { return s.StreamWheelOdometry(c); }, token, session_id, sensor, progress);
      case 5: return std::make_unique<TypedSensorStream<msgs::RadarMessage, v1::RadarMessage>>([&](grpc::ClientContext* c) { return s.StreamRadar(c); }, token, session_id, sensor, progress);
      case 6: return std::make_unique<TypedSensorStream<msgs::RangeMessage, v1::RangeMessage>>([&](grpc::ClientContext* c) { return s.StreamRange(c); }, token, session_id, sensor, progress);
      default: return std::make_unique<TypedSensorStream<msgs::DetectionsMessage, v1::DetectionsMessage>>([&](grpc::ClientContext* c) { return s.StreamDetections(c); }, token, session_id, sensor, progress);
    }
  }
};

FusionClient::FusionClient(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
FusionClient::~FusionClient() = default;

Result<std::unique_ptr<FusionClient>> FusionClient::create(const FusionClientConfig& config) {
  if (!config.rest_url.starts_with("http://") && !config.rest_url.starts_with("https://")) {
    return Error(fmt::format("REST URL '{}': expected http://HOST:PORT or https://HOST:PORT", config.rest_url));
  }
  if (config.grpc_address.empty()) return Error("gRPC address is empty (expected HOST:PORT)");
  auto impl = std::make_unique<Impl>();
  impl->config = config;
  impl->http = std::make_unique<httplib::Client>(config.rest_url);
  impl->http->set_read_timeout(60, 0);
  std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
  if (!config.tls_ca_file.empty()) {
    std::ifstream file(config.tls_ca_file);
    if (!file) return Error(fmt::format("{}: cannot read the CA certificate", config.tls_ca_file));
    std::stringstream pem;
    pem << file.rdbuf();
    grpc::SslCredentialsOptions options;
    options.pem_root_certs = pem.str();
    credentials = grpc::SslCredentials(options);
    impl->http->set_ca_cert_path(config.tls_ca_file.c_str());
  }
  impl->stub = v1::FusionService::NewStub(grpc::CreateChannel(config.grpc_address, credentials));
  return std::unique_ptr<FusionClient>(new FusionClient(std::move(impl)));
}

Result<std::string> FusionClient::create_session(const std::string& name, const std::string& config_yaml,
                                                 const std::string& calibration_yaml) {
  json body = {{"name", name}, {"config", config_yaml}};
  if (!calibration_yaml.empty()) body["calibration"] = calibration_yaml;
  const httplib::Result response = impl_->http->Post("/v1/sessions", impl_->headers(), body.dump(), "application/json");
  if (!response || response->status != 201) return http_error(response, "create session", impl_->config.rest_url);
  try {
    return json::parse(response->body).at("id").get<std::string>();
  } catch (const std::exception& error) {
    return Error(fmt::format("create session: unexpected answer: {}", error.what()));
  }
}

Result<std::string> FusionClient::get(const std::string& path) {
  const httplib::Result response = impl_->http->Get(path, impl_->headers());
  if (!response || response->status / 100 != 2) return http_error(response, "GET " + path, impl_->config.rest_url);
  return response->body;
}

Status FusionClient::end_session(const std::string& session_id) {
  const httplib::Result response = impl_->http->Delete("/v1/sessions/" + session_id, impl_->headers());
  if (!response || response->status != 200) return http_error(response, "end session", impl_->config.rest_url);
  return ok_status();
}

namespace {

// GET /v1/sessions/ID as a JSON object.
Result<json> session_state(FusionClient& client, const std::string& session_id) {
  std::string body;
  HANZO_ASSIGN_OR_RETURN(body, client.get("/v1/sessions/" + session_id));
  json parsed = json::parse(body, nullptr, false);
  if (!parsed.is_object()) return Error(fmt::format("GET /v1/sessions/{}: the answer is not a JSON object", session_id));
  return parsed;
}

}  // namespace

// Whether a stream the server ended with `status` is worth reopening: the server or its replica
// went away, a proxy reset the stream, or the session moved to another replica.
bool transient(const grpc::Status& status) {
  switch (status.error_code()) {
    case grpc::StatusCode::OK:  // the server stopped
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::UNKNOWN:
    case grpc::StatusCode::INTERNAL:
    case grpc::StatusCode::CANCELLED:
    case grpc::StatusCode::ABORTED:
      return true;
    default:
      return false;
  }
}

struct SessionStreams::State {
  FusionClient& client;
  FusionClient::Impl& impl;
  std::string session_id;
  json before;  // the session's state at open_streams()
  PoseProgress progress;
  std::map<std::string, std::unique_ptr<SensorStream>> streams;  // by sensor
  std::map<std::string, std::deque<msgs::SensorMessage>> recent;  // by sensor: the last replay_s sent
  std::optional<Clock::time_point> failing_since;  // a stream broke and no pose came back since
  uint64_t poses_when_failing = 0;
  StreamSummary summary;
  Clock::time_point started = Clock::now();

  void remember(const std::string& sensor, const msgs::SensorMessage& message) {
    std::deque<msgs::SensorMessage>& kept = recent[sensor];
    kept.push_back(message);
    const Timestamp newest = msgs::timestamp_of(message);
    while (kept.size() > 1 && (newest - msgs::timestamp_of(kept.front())).seconds() > impl.config.replay_s) kept.pop_front();
  }

  // Reopens the sensor's stream with backoff after the server ended it with `status`, sending
  // its recent messages again; the final status when it gave up.
  grpc::Status reconnect(const std::string& sensor, grpc::Status status) {
    if (failing_since && progress.received.load() > poses_when_failing) failing_since.reset();  // the last reconnect worked
    if (!failing_since) {
      failing_since = Clock::now();
      poses_when_failing = progress.received.load();
    }
    const auto deadline = *failing_since + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(impl.config.reconnect_timeout_s));
    std::chrono::milliseconds backoff(100);
    while (transient(status) && Clock::now() + backoff < deadline) {
      std::this_thread::sleep_for(backoff);
      backoff = std::min(backoff * 2, std::chrono::milliseconds(2000));
      const std::deque<msgs::SensorMessage>& messages = recent[sensor];
      std::unique_ptr<SensorStream> stream = impl.open_stream(messages.back(), session_id, sensor, progress);
      const bool written = std::all_of(messages.begin(), messages.end(), [&](const msgs::SensorMessage& m) { return stream->write(m); });
      if (written) {
        streams[sensor] = std::move(stream);
        ++summary.reconnects;
        logger()->info("stream {} of session {}: reopened after '{}' ({} recent messages sent again)", sensor, session_id,
                       status.error_message(), messages.size());
        return grpc::Status::OK;
      }
      status = stream->finish();
    }
    return status;
  }
};

SessionStreams::SessionStreams(std::unique_ptr<State> state) : state_(std::move(state)) {}
SessionStreams::~SessionStreams() = default;

Status SessionStreams::send(const std::string& sensor, const msgs::SensorMessage& message) {
  State& state = *state_;
  if (state.impl.config.reconnect_timeout_s > 0) state.remember(sensor, message);
  std::unique_ptr<SensorStream>& stream = state.streams[sensor];
  if (!stream) stream = state.impl.open_stream(message, state.session_id, sensor, state.progress);
  if (!stream->write(message)) {
    // The server ended the stream: its status says why (unknown session, permission, ...).
    grpc::Status status = stream->finish();
    stream.reset();
    if (state.impl.config.reconnect_timeout_s > 0) status = state.reconnect(sensor, status);
    if (!status.ok() || !state.streams[sensor]) {
      state.streams.erase(sensor);
      return Error(fmt::format("stream {} to {}: {}", sensor, state.impl.config.grpc_address,
                               status.ok() ? "the server closed the stream" : status.error_message()));
    }
  }
  ++state.summary.messages_sent;
  ++state.summary.sent_by_sensor[sensor];
  return ok_status();
}

std::optional<Timestamp> SessionStreams::newest_pose_time() const {
  const int64_t newest = state_->progress.newest_ns.load();
  if (newest == INT64_MIN) return std::nullopt;
  return Timestamp::from_nanoseconds(newest);
}

Result<StreamSummary> SessionStreams::finish() {
  State& state = *state_;
  Status outcome = ok_status();
  for (auto& [sensor, stream] : state.streams) {
    const grpc::Status status = stream->finish();
    if (!status.ok() && outcome) outcome = Error(fmt::format("stream {} to {}: {}", sensor, state.impl.config.grpc_address, status.error_message()));
  }
  state.streams.clear();
  if (!outcome) return outcome.error();
  json after;
  HANZO_ASSIGN_OR_RETURN(after, session_state(state.client, state.session_id));
  StreamSummary summary = state.summary;
  summary.accepted = accepted_messages(after) - std::min(accepted_messages(after), accepted_messages(state.before));
  summary.wall_seconds = std::chrono::duration<double>(Clock::now() - state.started).count();
  summary.poses_received = state.progress.received.load();
  std::lock_guard lock(state.progress.mutex);
  summary.latest_pose = state.progress.latest;
  return summary;
}

Result<std::unique_ptr<SessionStreams>> FusionClient::open_streams(const std::string& session_id) {
  json before;
  HANZO_ASSIGN_OR_RETURN(before, session_state(*this, session_id));
  auto state = std::unique_ptr<SessionStreams::State>(new SessionStreams::State{*this, *impl_, session_id, std::move(before), {}, {}, {}, {}, 0, {}, Clock::now()});
  return std::unique_ptr<SessionStreams>(new SessionStreams(std::move(state)));
}

Result<StreamSummary> FusionClient::stream_log(const std::string& log_path, const std::string& session_id, const StreamOptions& options) {
  if (!(options.rate >= 0) || !(options.max_lead_s > 0) || !(options.stall_timeout_s > 0)) {
    return Error("stream: rate must be >= 0, max_lead_s and stall_timeout_s > 0");
  }
  std::unique_ptr<io::SensorLogReader> reader;
  HANZO_ASSIGN_OR_RETURN(reader, io::SensorLogReader::open(log_path));
  std::unique_ptr<SessionStreams> streams;
  HANZO_ASSIGN_OR_RETURN(streams, open_streams(session_id));
  // The session's configuration maps topics.
  std::map<std::string, std::string> sensor_by_topic = options.sensor_by_topic;
  if (sensor_by_topic.empty()) {
    auto configuration = config::parse_fusion_config(streams->state_->before.value("config", ""), "the configuration of session " + session_id);
    if (!configuration) return configuration.error();
    for (const config::SensorConfig& sensor : configuration->sensors) sensor_by_topic[sensor.topic] = sensor.name;
  }
  std::map<std::string, uint64_t> skipped_by_topic;
  std::optional<Timestamp> first_time;
  double log_seconds = 0.0;
  const auto started = Clock::now();
  io::LogEntry entry;
  Status outcome = ok_status();
  while (true) {
    Result<bool> more = reader->next(entry);
    if (!more) {
      outcome = with_context(Status(more.error()), log_path);
      break;
    }
    if (!*more) break;
    const auto* message = std::get_if<msgs::SensorMessage>(&entry.message);
    const auto mapped = sensor_by_topic.find(entry.topic);
    if (message == nullptr || mapped == sensor_by_topic.end()) {
      if (message != nullptr && skipped_by_topic[entry.topic] == 0) {
        logger()->warn("stream: no sensor of session '{}' reads topic '{}'; its messages are skipped", session_id, entry.topic);
      }
      ++skipped_by_topic[entry.topic];
      continue;
    }
    const Timestamp time = entry.log_time;
    if (!first_time) first_time = time;
    log_seconds = (time - *first_time).seconds();
    // Pacing: the log's clock scaled by rate, or the server's progress.
    if (options.rate > 0) {
      std::this_thread::sleep_until(started + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(log_seconds / options.rate)));
    } else {
      const auto waiting_since = Clock::now();
      const int64_t allowed_ahead = static_cast<int64_t>(options.max_lead_s * 1e9);
      for (std::optional<Timestamp> newest = streams->newest_pose_time(); newest && time.nanoseconds() - newest->nanoseconds() > allowed_ahead;
           newest = streams->newest_pose_time()) {
        if (std::chrono::duration<double>(Clock::now() - waiting_since).count() > options.stall_timeout_s) {
          return Error(fmt::format("stream: the server sent no pose past {:.3f} s for {} s (is the session still fusing?)", newest->seconds(),
                                   options.stall_timeout_s));
        }
        std::this_thread::sleep_for(std::chrono::microseconds(200));
      }
    }
    if (Status sent = streams->send(mapped->second, *message); !sent) return Error(fmt::format("{} ({})", sent.error().message, entry.topic));
  }
  if (outcome) outcome = with_context(reader->complete(), log_path);  // a partial log streamed is said so
  Result<StreamSummary> summary = streams->finish();
  if (!outcome) return outcome.error();
  if (!summary) return summary.error();
  summary->skipped_by_topic = std::move(skipped_by_topic);
  summary->log_seconds = log_seconds;
  return summary;
}

}  // namespace hanzo::fusion::service
