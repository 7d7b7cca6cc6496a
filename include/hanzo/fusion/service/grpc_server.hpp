#pragma once
// The gRPC streaming API on port 8084 (proto/hanzo/fusion/v1/service.proto, FusionService).
//
// Calls carry metadata:
//   authorization: Bearer TOKEN        (as REST; UNAUTHENTICATED / PERMISSION_DENIED)
//   x-session-id: ID                   (Stream* calls: the session the messages go to)
//   x-sensor: NAME                     (optional: the configured sensor; default the session's
//                                       only sensor of the stream's modality)
//
// Stream{Imu,PointCloud,Image,Gnss,Radar,Range,WheelOdometry}: every message read is pushed into the
// session; after each message the newest PoseEstimate since the previous write is written back
// (the IMU stream thereby gets every pose, a LiDAR stream one per sweep). A message that does not decode or that
// the session rejects is counted (hanzo_fusion_stream_rejected_total{reason}) and skipped: the
// stream goes on. The stream ends with FAILED_PRECONDITION when the session ends, and with the
// error's status when the session is unknown or not the caller's.
// SubscribePose(SessionId): the session's PoseEstimates until the client cancels or the session
// ends; a slow subscriber loses the oldest (counted), never blocks fusion.
// SubscribeKeyframes, SubscribeMap: the session's keyframes / map updates, the same way.
// GetMap: a session's live map or a stored version of a map of the caller's organization.
// LoadMap: stores a client's map as the next version of its map id.
// One thread per open call (gRPC's synchronous server): a push may wait for the session's
// registration worker, which must not stall other calls.
//
// TLS when tls_certificate and tls_private_key (PEM) are given.

#include <memory>
#include <string>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/service/auth.hpp"
#include "hanzo/fusion/service/metrics.hpp"
#include "hanzo/fusion/service/session_manager.hpp"

namespace hanzo::fusion::service {

struct GrpcServerConfig {
  std::string bind_address = "0.0.0.0";
  int port = 8084;                        // 0 picks a free port
  std::string tls_certificate;
  std::string tls_private_key;
  int max_message_bytes = 64 << 20;       // a LiDAR scan of ~1.5M points
};

class GrpcServer {
 public:
  /// `tokens` null turns authentication off (every call is Principal::local_development()).
  static Result<std::unique_ptr<GrpcServer>> create(const GrpcServerConfig& config, SessionManager& sessions,
                                                    std::shared_ptr<const TokenStore> tokens,
                                                    std::shared_ptr<MetricsRegistry> metrics);
  ~GrpcServer();
  GrpcServer(const GrpcServer&) = delete;
  GrpcServer& operator=(const GrpcServer&) = delete;

  /// Binds and serves on gRPC's threads; fails naming the address when it cannot bind.
  Status start();
  int port() const;
  /// Ends every call (subscriptions close) and stops.
  void stop();

 private:
  struct Impl;
  explicit GrpcServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace hanzo::fusion::service
