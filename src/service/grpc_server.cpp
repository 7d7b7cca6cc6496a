#include "hanzo/fusion/service/grpc_server.hpp"

#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>
#include <grpcpp/grpcpp.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/msgs/convert.hpp"
#include "hanzo/fusion/msgs/map_convert.hpp"
#include "hanzo/fusion/v1/service.grpc.pb.h"

namespace hanzo::fusion::service {
namespace {

grpc::StatusCode grpc_code(ErrorCode code) {
  switch (code) {
    case ErrorCode::kInvalidArgument: return grpc::StatusCode::INVALID_ARGUMENT;
    case ErrorCode::kUnauthenticated: return grpc::StatusCode::UNAUTHENTICATED;
    case ErrorCode::kPermissionDenied: return grpc::StatusCode::PERMISSION_DENIED;
    case ErrorCode::kNotFound: return grpc::StatusCode::NOT_FOUND;
    case ErrorCode::kConflict: return grpc::StatusCode::FAILED_PRECONDITION;
    case ErrorCode::kPayloadTooLarge: return grpc::StatusCode::RESOURCE_EXHAUSTED;
    case ErrorCode::kRejected: return grpc::StatusCode::FAILED_PRECONDITION;
    case ErrorCode::kResourceExhausted: return grpc::StatusCode::RESOURCE_EXHAUSTED;
    case ErrorCode::kInternal: return grpc::StatusCode::INTERNAL;
    case ErrorCode::kUnavailable: return grpc::StatusCode::UNAVAILABLE;
  }
  return grpc::StatusCode::INTERNAL;
}

grpc::Status to_grpc(const ApiError& error) {
  // A session another replica serves: UNAVAILABLE (clients retry; behind the load balancer the
  // retry reaches the session's replica, or this one once it has taken the session over).
  const std::string message = error.served_by.empty() ? error.message : fmt::format("{} ({})", error.message, error.served_by);
  return {grpc_code(error.code), message, std::string(to_string(error.code)) + (error.field.empty() ? "" : ":" + error.field)};
}

std::string metadata(const grpc::ServerContext& context, const std::string& key) {
  const auto& entries = context.client_metadata();
  const auto found = entries.find(key);
  return found == entries.end() ? std::string() : std::string(found->second.data(), found->second.size());
}

Result<std::string> read_pem(const std::string& path) {
  std::ifstream file(path);
  if (!file) return Error(fmt::format("{}: cannot read", path));
  return std::string(std::istreambuf_iterator<char>(file), {});
}

class FusionServiceImpl final : public v1::FusionService::Service {
 public:
  FusionServiceImpl(SessionManager& sessions, std::shared_ptr<const TokenStore> tokens, MetricsRegistry& metrics)
      : sessions_(sessions), tokens_(std::move(tokens)), metrics_(metrics) {}

  void stop() { stopping_ = true; }

  grpc::Status StreamImu(grpc::ServerContext* context, grpc::ServerReaderWriter<v1::PoseEstimate, v1::ImuMessage>* stream) override {
    return serve_stream(*context, *stream, "imu");
  }
  grpc::Status StreamPointCloud(grpc::ServerContext* context,
                                grpc::ServerReaderWriter<v1::PoseEstimate, v1::PointCloudMessage>* stream) override {
    return serve_stream(*context, *stream, "point_cloud");
  }
  grpc::Status StreamImage(grpc::ServerContext* context, grpc::ServerReaderWriter<v1::PoseEstimate, v1::ImageMessage>* stream) override {
    return serve_stream(*context, *stream, "image");
  }
  grpc::Status StreamGnss(grpc::ServerContext* context, grpc::ServerReaderWriter<v1::PoseEstimate, v1::GnssMessage>* stream) override {
    return serve_stream(*context, *stream, "gnss");
  }
  grpc::Status StreamRadar(grpc::ServerContext* context, grpc::ServerReaderWriter<v1::PoseEstimate, v1::RadarMessage>* stream) override {
    return serve_stream(*context, *stream, "radar");
  }
  grpc::Status StreamRange(grpc::ServerContext* context, grpc::ServerReaderWriter<v1::PoseEstimate, v1::RangeMessage>* stream) override {
    return serve_stream(*context, *stream, "range");
  }
  grpc::Status StreamDetections(grpc::ServerContext* context, grpc::ServerReaderWriter<v1::PoseEstimate, v1::DetectionsMessage>* stream) override {
    return serve_stream(*context, *stream, "detections");
  }
  grpc::Status StreamWheelOdometry(grpc::ServerContext* context,
                                   grpc::ServerReaderWriter<v1::PoseEstimate, v1::WheelOdometryMessage>* stream) override {
    return serve_stream(*context, *stream, "wheel_odometry");
  }

  grpc::Status SubscribePose(grpc::ServerContext* context, const v1::SessionId* request,
                             grpc::ServerWriter<v1::PoseEstimate>* writer) override {
    return serve_subscription(*context, *writer, request->id(), [&](const Principal& caller) { return sessions_.subscribe_poses(caller, request->id()); });
  }
  grpc::Status SubscribeKeyframes(grpc::ServerContext* context, const v1::SessionId* request,
                                  grpc::ServerWriter<v1::Keyframe>* writer) override {
    return serve_subscription(*context, *writer, request->id(), [&](const Principal& caller) { return sessions_.subscribe_keyframes(caller, request->id()); });
  }
  grpc::Status SubscribeMap(grpc::ServerContext* context, const v1::SessionId* request,
                            grpc::ServerWriter<v1::MapUpdate>* writer) override {
    return serve_subscription(*context, *writer, request->id(), [&](const Principal& caller) { return sessions_.subscribe_map(caller, request->id()); });
  }

  // A session's map (session_id; map_id empty or the session id; version 0 = the live map) or
  // a stored version of any map of the caller's organization (map_id; version 0 = the latest).
  grpc::Status GetMap(grpc::ServerContext* context, const v1::MapRequest* request, v1::FusionMap* response) override {
    auto principal = authenticate(*context);
    if (!principal) return to_grpc(principal.error());
    if (request->session_id().empty() && request->map_id().empty()) return {grpc::StatusCode::INVALID_ARGUMENT, "give session_id or map_id"};
    const std::string& map_id = request->map_id().empty() ? request->session_id() : request->map_id();
    ApiResult<msgs::FusionMap> map = ApiError{};
    if (request->version() == 0 && map_id == request->session_id()) {
      if (const ApiStatus here = sessions_.serve_here(principal.value(), request->session_id()); !here) return to_grpc(here.error());
      map = sessions_.map(principal.value(), request->session_id());
    } else {
      map = sessions_.stored_map(principal.value(), map_id,
                                 request->version() == 0 ? std::nullopt : std::optional<uint64_t>(request->version()));
    }
    if (!map) return to_grpc(map.error());
    *response = msgs::to_proto(map.value());
    return grpc::Status::OK;
  }

  // Stores the map as the next version of its map_id (a new id when empty).
  grpc::Status LoadMap(grpc::ServerContext* context, const v1::FusionMap* request, v1::LoadMapResponse* response) override {
    auto principal = authenticate(*context);
    if (!principal) return to_grpc(principal.error());
    Result<msgs::FusionMap> map = msgs::from_proto(*request);
    if (!map) return {grpc::StatusCode::INVALID_ARGUMENT, map.error().message};
    auto saved = sessions_.load_map(principal.value(), std::move(map).value());
    if (!saved) return to_grpc(saved.error());
    response->set_map_id(saved->map_id);
    response->set_version(saved->version);
    return grpc::Status::OK;
  }

 private:
  ApiResult<Principal> authenticate(const grpc::ServerContext& context) const {
    return authenticate_bearer(tokens_.get(), metadata(context, "authorization"), "authorization");
  }

  // Writes what a subscription of the caller's (made by `subscribe`) receives until the client
  // goes away, the server stops or the session ends (FAILED_PRECONDITION).
  template <typename ProtoMessage, typename Subscribe>
  grpc::Status serve_subscription(grpc::ServerContext& context, grpc::ServerWriter<ProtoMessage>& writer, const std::string& session_id,
                                  Subscribe subscribe) {
    auto principal = authenticate(context);
    if (!principal) return to_grpc(principal.error());
    if (const ApiStatus here = sessions_.serve_here(principal.value(), session_id); !here) return to_grpc(here.error());
    auto subscription = subscribe(principal.value());
    if (!subscription) return to_grpc(subscription.error());
    auto& queue = *subscription.value();
    while (!context.IsCancelled() && !stopping_) {
      auto value = queue.pop(std::chrono::milliseconds(100));
      if (!value) {
        if (!queue.closed()) continue;
        // Closed: the session ended, or (replicas) moved to another replica, where a retry gets it.
        if (auto info = sessions_.session_info(principal.value(), session_id); !info && !info.error().served_by.empty()) {
          return to_grpc(info.error());
        }
        return {grpc::StatusCode::FAILED_PRECONDITION, "the session ended"};
      }
      if (!writer.Write(msgs::to_proto(*value))) break;  // the client went away
    }
    queue.close();
    return grpc::Status::OK;
  }

  template <typename ProtoMessage>
  grpc::Status serve_stream(grpc::ServerContext& context, grpc::ServerReaderWriter<v1::PoseEstimate, ProtoMessage>& stream,
                            const std::string& modality) {
    auto principal = authenticate(context);
    if (!principal) return to_grpc(principal.error());
    const std::string session_id = metadata(context, "x-session-id");
    if (session_id.empty()) return {grpc::StatusCode::INVALID_ARGUMENT, "metadata 'x-session-id' is missing"};
    const std::string sensor = metadata(context, "x-sensor");
    // Checks access before the first message arrives (writing needs session:write, the poses
    // answered need session:read), and collects the session's poses.
    if (const ApiStatus allowed = authorize(principal.value(), Permission::kSessionWrite); !allowed) return to_grpc(allowed.error());
    // Replicas: a stream cannot be forwarded; the session moves to the replica it reached.
    if (const ApiStatus here = sessions_.serve_here(principal.value(), session_id); !here) return to_grpc(here.error());
    auto subscription = sessions_.subscribe_poses(principal.value(), session_id);
    if (!subscription) return to_grpc(subscription.error());
    PoseSubscription& poses = *subscription.value();
    Counter& received = metrics_.counter("hanzo_fusion_stream_messages_total", "Messages read from gRPC streams", {{"modality", modality}});
    ProtoMessage in;
    grpc::Status outcome = grpc::Status::OK;
    bool warned_unknown_sensor = false;  // once per stream: each of its messages names the same sensor
    while (!stopping_ && stream.Read(&in)) {
      received.increment();
      auto message = msgs::from_proto(in);
      if (!message) {
        reject("decode", modality, message.error().message);
        continue;
      }
      const ApiStatus pushed = sessions_.push(principal.value(), session_id, sensor, msgs::SensorMessage(std::move(message).value()));
      if (!pushed) {
        if (pushed.error().code != ErrorCode::kRejected && pushed.error().code != ErrorCode::kInvalidArgument) {
          outcome = to_grpc(pushed.error());
          break;
        }
        reject(pushed.error().code == ErrorCode::kRejected ? "session" : "sensor", modality, pushed.error().message);
        if (pushed.error().field == "sensor" && !warned_unknown_sensor) {
          warned_unknown_sensor = true;
          logger()->warn("gRPC {} stream into session '{}' (x-sensor '{}'): {}; its messages are dropped", modality, session_id, sensor,
                         pushed.error().message);
        }
      }
      // Answers at the stream's own rate: the newest pose since its previous message. The IMU's
      // stream thereby gets every pose (each IMU sample makes one); a LiDAR stream one per
      // sweep, not the 20 IMU poses between sweeps (SubscribePose gives every pose).
      std::optional<msgs::PoseEstimate> newest;
      while (std::optional<msgs::PoseEstimate> pose = poses.pop(std::chrono::milliseconds(0))) newest = std::move(pose);
      if (newest && !stream.Write(msgs::to_proto(*newest))) break;  // the client went away
    }
    poses.close();
    return outcome;
  }

  void reject(const std::string& reason, const std::string& modality, const std::string& message) {
    metrics_.counter("hanzo_fusion_stream_rejected_total", "Stream messages skipped, by reason",
                     {{"modality", modality}, {"reason", reason}})
        .increment();
    logger()->debug("gRPC {} stream: skipped a message: {}", modality, message);
  }

  SessionManager& sessions_;
  std::shared_ptr<const TokenStore> tokens_;
  MetricsRegistry& metrics_;
  std::atomic<bool> stopping_{false};
};

}  // namespace

struct GrpcServer::Impl {
  GrpcServerConfig config;
  std::shared_ptr<MetricsRegistry> metrics;
  std::shared_ptr<grpc::ServerCredentials> credentials;
  std::unique_ptr<FusionServiceImpl> service;
  std::unique_ptr<grpc::Server> server;
  int bound_port = 0;
};

GrpcServer::GrpcServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

GrpcServer::~GrpcServer() { stop(); }

Result<std::unique_ptr<GrpcServer>> GrpcServer::create(const GrpcServerConfig& config, SessionManager& sessions,
                                                       std::shared_ptr<const TokenStore> tokens,
                                                       std::shared_ptr<MetricsRegistry> metrics) {
  auto impl = std::make_unique<Impl>();
  impl->config = config;
  impl->metrics = metrics ? std::move(metrics) : std::make_shared<MetricsRegistry>();
  if (!config.tls_certificate.empty() || !config.tls_private_key.empty()) {
    if (config.tls_certificate.empty() || config.tls_private_key.empty()) {
      return Error("gRPC TLS needs both a certificate and a private key file");
    }
    grpc::SslServerCredentialsOptions::PemKeyCertPair pair;
    HANZO_ASSIGN_OR_RETURN(pair.cert_chain, read_pem(config.tls_certificate));
    HANZO_ASSIGN_OR_RETURN(pair.private_key, read_pem(config.tls_private_key));
    grpc::SslServerCredentialsOptions options;
    options.pem_key_cert_pairs.push_back(pair);
    impl->credentials = grpc::SslServerCredentials(options);
  } else {
    impl->credentials = grpc::InsecureServerCredentials();
  }
  impl->service = std::make_unique<FusionServiceImpl>(sessions, std::move(tokens), *impl->metrics);
  return std::unique_ptr<GrpcServer>(new GrpcServer(std::move(impl)));
}

Status GrpcServer::start() {
  Impl& impl = *impl_;
  grpc::ServerBuilder builder;
  const std::string address = fmt::format("{}:{}", impl.config.bind_address, impl.config.port);
  builder.AddListeningPort(address, impl.credentials, &impl.bound_port);
  builder.SetMaxReceiveMessageSize(impl.config.max_message_bytes);
  builder.SetMaxSendMessageSize(impl.config.max_message_bytes);
  builder.RegisterService(impl.service.get());
  impl.server = builder.BuildAndStart();
  if (!impl.server || impl.bound_port == 0) {
    impl.server.reset();
    return Error(fmt::format("cannot serve gRPC on {} (in use, no permission, or bad TLS files)", address));
  }
  logger()->info("gRPC API on {}:{}", impl.config.bind_address, impl.bound_port);
  return ok_status();
}

int GrpcServer::port() const { return impl_->bound_port; }

void GrpcServer::stop() {
  if (!impl_ || !impl_->server) return;
  impl_->service->stop();
  impl_->server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
  impl_->server->Wait();
  impl_->server.reset();
}

}  // namespace hanzo::fusion::service
