#include <thread>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/msgs/convert.hpp"
#include "hanzo/fusion/service/grpc_server.hpp"
#include "hanzo/fusion/v1/service.grpc.pb.h"
#include "service_fixtures.hpp"

namespace hanzo::fusion::service {
namespace {

using ::testing::HasSubstr;

const Principal kOwner{"robot", "acme", static_cast<uint32_t>(Permission::kSessionWrite) | static_cast<uint32_t>(Permission::kSessionRead)};

class GrpcServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    auto storage = open_storage("sqlite://" + (testing::scratch_dir() / "fusion.db").string());
    ASSERT_TRUE(storage.ok());
    metrics_ = std::make_shared<MetricsRegistry>();
    manager_ = std::move(SessionManager::create({}, std::move(storage).value(), metrics_)).value();
    auto tokens = TokenStore::parse(testing::kTokensYaml, "tokens.yaml");
    ASSERT_TRUE(tokens.ok());
    GrpcServerConfig config;
    config.bind_address = "127.0.0.1";
    config.port = 0;
    auto server = GrpcServer::create(config, *manager_, std::make_shared<TokenStore>(std::move(tokens).value()), metrics_);
    ASSERT_TRUE(server.ok()) << server.error().message;
    server_ = std::move(server).value();
    ASSERT_TRUE(server_->start().ok());
    stub_ = v1::FusionService::NewStub(
        grpc::CreateChannel("127.0.0.1:" + std::to_string(server_->port()), grpc::InsecureChannelCredentials()));
    session_id_ = manager_->create_session(kOwner, {"grpc", testing::read_text("examples/data/fusion.yaml"), ""}).value().id;
  }

  static void prepare(grpc::ClientContext& context, const std::string& token, const std::string& session_id) {
    if (!token.empty()) context.AddMetadata("authorization", "Bearer " + token);
    if (!session_id.empty()) context.AddMetadata("x-session-id", session_id);
  }

  std::shared_ptr<MetricsRegistry> metrics_;
  std::unique_ptr<SessionManager> manager_;
  std::unique_ptr<GrpcServer> server_;
  std::unique_ptr<v1::FusionService::Stub> stub_;
  std::string session_id_;
};

TEST_F(GrpcServerTest, StreamsTheSampleRecordingAndReturnsPosesAtImuRate) {
  grpc::ClientContext imu_context, gnss_context, wheel_context, subscribe_context;
  for (grpc::ClientContext* context : {&imu_context, &gnss_context, &wheel_context}) prepare(*context, "acme-robot-secret-0001", session_id_);
  prepare(subscribe_context, "acme-viewer-secret-0002", "");
  auto imu = stub_->StreamImu(&imu_context);
  auto gnss = stub_->StreamGnss(&gnss_context);
  auto wheels = stub_->StreamWheelOdometry(&wheel_context);
  v1::SessionId session;
  session.set_id(session_id_);
  auto subscription = stub_->SubscribePose(&subscribe_context, session);

  // Poses come back on the IMU stream (read concurrently, as a client must) and on the subscription.
  std::vector<v1::PoseEstimate> streamed, subscribed;
  std::thread imu_reader([&] {
    v1::PoseEstimate pose;
    while (imu->Read(&pose)) streamed.push_back(pose);
  });
  std::thread subscription_reader([&] {
    v1::PoseEstimate pose;
    while (subscription->Read(&pose)) subscribed.push_back(pose);
  });
  std::thread drain_gnss([&] { v1::PoseEstimate pose; while (gnss->Read(&pose)) {} });
  std::thread drain_wheels([&] { v1::PoseEstimate pose; while (wheels->Read(&pose)) {} });

  // Three streams are three independent channels: a replay faster than real time would let one
  // run ahead of the others by more than the lag window. Like a real-time robot, write the next
  // message once the server has taken the previous one.
  std::size_t imu_messages = 0;
  uint64_t written = 0;
  auto wait_until_received = [&] {
    ++written;
    while (true) {
      const pipeline::SessionSummary summary = manager_->session_info(kOwner, session_id_)->summary;
      uint64_t received = 0;
      for (const pipeline::SensorStatistics& sensor : summary.sensors) received += sensor.received;
      if (received >= written) return;
      std::this_thread::yield();
    }
  };
  for (const testing::TimedMessage& message : testing::sample_recording()) {
    if (const auto* m = std::get_if<msgs::ImuMessage>(&message.message)) {
      ASSERT_TRUE(imu->Write(msgs::to_proto(*m)));
      ++imu_messages;
    } else if (const auto* g = std::get_if<msgs::GnssMessage>(&message.message)) {
      ASSERT_TRUE(gnss->Write(msgs::to_proto(*g)));
    } else if (const auto* w = std::get_if<msgs::WheelOdometryMessage>(&message.message)) {
      ASSERT_TRUE(wheels->Write(msgs::to_proto(*w)));
    }
    wait_until_received();
  }
  // A message that does not decode is skipped; the stream goes on.
  v1::ImuMessage broken;
  broken.set_timestamp_ns(1);
  broken.mutable_linear_acceleration()->set_x(std::numeric_limits<double>::quiet_NaN());
  ASSERT_TRUE(imu->Write(broken));
  imu->WritesDone();
  gnss->WritesDone();
  wheels->WritesDone();
  imu_reader.join();
  drain_gnss.join();
  drain_wheels.join();
  EXPECT_TRUE(imu->Finish().ok());
  EXPECT_TRUE(gnss->Finish().ok());
  EXPECT_TRUE(wheels->Finish().ok());

  const SessionInfo info = manager_->session_info(kOwner, session_id_).value();
  EXPECT_EQ(info.summary.sensors[0].received, imu_messages);  // the broken one never reached the session
  EXPECT_THAT(metrics_->render(), HasSubstr("hanzo_fusion_stream_rejected_total{modality=\"imu\",reason=\"decode\"} 1.0"));
  EXPECT_GT(info.summary.poses, 1800u);
  // The IMU stream carries every pose produced while it was the writer (GNSS / wheel updates
  // emit none of their own), in time order.
  EXPECT_GE(streamed.size(), info.summary.poses - 2);
  for (std::size_t i = 1; i < streamed.size(); ++i) EXPECT_LT(streamed[i - 1].timestamp_ns(), streamed[i].timestamp_ns());
  ASSERT_FALSE(streamed.empty());
  EXPECT_EQ(streamed.back().timestamp_ns(), static_cast<uint64_t>(info.latest_pose->timestamp.nanoseconds()));

  ASSERT_TRUE(manager_->end_session(kOwner, session_id_).ok());
  subscription_reader.join();
  const grpc::Status ended = subscription->Finish();
  EXPECT_EQ(ended.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(subscribed.size(), info.summary.poses);
}

TEST_F(GrpcServerTest, AuthErrorsMapToGrpcStatus) {
  auto open_imu_stream = [&](const std::string& token, const std::string& session_id) {
    grpc::ClientContext context;
    prepare(context, token, session_id);
    auto stream = stub_->StreamImu(&context);
    stream->WritesDone();
    return stream->Finish();
  };
  EXPECT_EQ(open_imu_stream("", session_id_).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(open_imu_stream("wrong-token-0123456789", session_id_).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(open_imu_stream("globex-robot-secret-0004", session_id_).error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(open_imu_stream("acme-robot-secret-0001", "").error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(open_imu_stream("acme-robot-secret-0001", "ffffffff").error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(open_imu_stream("acme-robot-secret-0001", session_id_).ok());

  grpc::ClientContext context;
  prepare(context, "globex-robot-secret-0004", "");
  v1::SessionId session;
  session.set_id(session_id_);
  v1::PoseEstimate pose;
  auto reader = stub_->SubscribePose(&context, session);
  EXPECT_FALSE(reader->Read(&pose));
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::PERMISSION_DENIED);

  // Map RPCs: another organization's session, a request without a session.
  for (const char* token : {"globex-robot-secret-0004", "acme-robot-secret-0001"}) {
    grpc::ClientContext map_context;
    prepare(map_context, token, "");
    v1::MapRequest request;
    if (std::string(token).starts_with("globex")) request.set_session_id(session_id_);
    v1::FusionMap map;
    EXPECT_EQ(stub_->GetMap(&map_context, request, &map).error_code(),
              request.session_id().empty() ? grpc::StatusCode::INVALID_ARGUMENT : grpc::StatusCode::PERMISSION_DENIED);
  }
  grpc::ClientContext keyframes_context;
  prepare(keyframes_context, "globex-robot-secret-0004", "");
  v1::Keyframe keyframe;
  auto keyframes = stub_->SubscribeKeyframes(&keyframes_context, session);
  EXPECT_FALSE(keyframes->Read(&keyframe));
  EXPECT_EQ(keyframes->Finish().error_code(), grpc::StatusCode::PERMISSION_DENIED);
}

}  // namespace
}  // namespace hanzo::fusion::service
