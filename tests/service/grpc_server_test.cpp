#include <functional>
#include <map>
#include <set>
#include <thread>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/msgs/convert.hpp"
#include "hanzo/fusion/msgs/map_convert.hpp"
#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/service/grpc_server.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "hanzo/fusion/v1/service.grpc.pb.h"
#include "service_fixtures.hpp"

namespace hanzo::fusion::service {
namespace {

using ::testing::HasSubstr;

const Principal kOwner{"robot", "acme", static_cast<uint32_t>(Permission::kSessionWrite) | static_cast<uint32_t>(Permission::kSessionRead)};

class GrpcServerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::filesystem::path dir = testing::scratch_dir();  // once: each call empties it
    auto storage = open_storage("sqlite://" + (dir / "fusion.db").string());
    ASSERT_TRUE(storage.ok());
    metrics_ = std::make_shared<MetricsRegistry>();
    SessionManagerConfig manager_config;
    manager_config.map_directory = (dir / "maps").string();
    manager_ = std::move(SessionManager::create(manager_config, std::move(storage).value(), metrics_)).value();
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
  std::size_t wheel_poses = 0, wheel_messages = 0;
  std::thread drain_wheels([&] { v1::PoseEstimate pose; while (wheels->Read(&pose)) ++wheel_poses; });

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
      ++wheel_messages;
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
  // The other streams answer at their own rate: at most the newest pose after each message.
  EXPECT_GT(wheel_poses, wheel_messages / 2);
  EXPECT_LE(wheel_poses, wheel_messages);
  for (std::size_t i = 1; i < streamed.size(); ++i) EXPECT_LT(streamed[i - 1].timestamp_ns(), streamed[i].timestamp_ns());
  ASSERT_FALSE(streamed.empty());
  EXPECT_EQ(streamed.back().timestamp_ns(), static_cast<uint64_t>(info.latest_pose->timestamp.nanoseconds()));

  ASSERT_TRUE(manager_->end_session(kOwner, session_id_).ok());
  subscription_reader.join();
  const grpc::Status ended = subscription->Finish();
  EXPECT_EQ(ended.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(subscribed.size(), info.summary.poses);
}

// StreamImage fuses: a session configured with the simulated drone's stereo cameras (no IMU)
// takes their images over two gRPC streams and tracks them with visual odometry.
TEST_F(GrpcServerTest, StreamImageFusesStereoCamerasThroughVisualOdometry) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/drone.yaml").value();
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& sensor) { return sensor.modality != config::SensorModality::kCamera; });
  scenario.duration = 3.0;  // 2 s standing, then the start of the flight
  scenario.num_threads = 0;
  const std::string config_yaml = config::to_yaml(sim::scenario_fusion_config(scenario));
  const std::string calibration_yaml = calib::to_yaml(sim::scenario_calibration(scenario));
  const std::string cameras = manager_->create_session(kOwner, {"cameras", config_yaml, calibration_yaml}).value().id;
  grpc::ClientContext left_context, right_context;
  prepare(left_context, "acme-robot-secret-0001", cameras);
  prepare(right_context, "acme-robot-secret-0001", cameras);
  left_context.AddMetadata("x-sensor", "camera_left");
  right_context.AddMetadata("x-sensor", "camera_right");
  auto left = stub_->StreamImage(&left_context);
  auto right = stub_->StreamImage(&right_context);
  std::thread drain_left([&] { v1::PoseEstimate pose; while (left->Read(&pose)) {} });
  std::thread drain_right([&] { v1::PoseEstimate pose; while (right->Read(&pose)) {} });
  uint64_t written = 0;
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  ASSERT_TRUE(simulation->run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) {
    const auto& image = std::get<msgs::ImageMessage>(message);
    EXPECT_TRUE((sensor.name == "camera_left" ? left : right)->Write(msgs::to_proto(image)));
    // One stream after the other, in the log's order: the left image of a time before its right.
    ++written;
    while (true) {
      const SessionInfo now = manager_->session_info(kOwner, cameras).value();
      uint64_t received = 0;
      for (const pipeline::SensorStatistics& sensor_statistics : now.summary.sensors) received += sensor_statistics.received;
      if (received >= written) break;
      std::this_thread::yield();
    }
    return ok_status();
  }).ok());
  left->WritesDone();
  right->WritesDone();
  drain_left.join();
  drain_right.join();
  EXPECT_TRUE(left->Finish().ok());
  EXPECT_TRUE(right->Finish().ok());
  const SessionInfo info = manager_->session_info(kOwner, cameras).value();
  EXPECT_EQ(info.mapping.camera_frames_tracked, 31u);  // 10 Hz over 3 s, both ends
  EXPECT_FALSE(info.mapping.visual_scale_free);
  for (const pipeline::SensorStatistics& sensor : info.summary.sensors) EXPECT_EQ(sensor.fused, 31u) << sensor.name;
  ASSERT_TRUE(info.latest_pose.has_value());
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

template <typename Request, typename Response>
grpc::Status close_stream(std::unique_ptr<grpc::ClientReaderWriter<Request, Response>> stream) {
  stream->WritesDone();
  Response response;
  while (stream->Read(&response)) {
  }
  return stream->Finish();
}

template <typename Response>
grpc::Status drain(std::unique_ptr<grpc::ClientReader<Response>> reader) {
  Response response;
  while (reader->Read(&response)) {
  }
  return reader->Finish();
}

// The auth matrix of every RPC of FusionService, enumerated from its descriptor (a new RPC fails
// here until it is listed with its permissions): no token or an unknown one: UNAUTHENTICATED; an
// acme token lacking the permission: PERMISSION_DENIED; another organization's admin on acme's
// session or map: PERMISSION_DENIED (sensor streams need session:write to write and
// session:read for the poses they answer); a token with the permission: neither (subscriptions run
// into their deadline, streams end, GetMap may find no map yet).
TEST_F(GrpcServerTest, AuthMatrixOfEveryRpc) {
  msgs::FusionMap stored;
  stored.map_id = "grpc-auth";
  stored.points = msgs::PointLayer{};
  stored.points->points = {Eigen::Vector3f(1.0F, 2.0F, 0.5F), Eigen::Vector3f(2.0F, 1.0F, 0.5F)};
  const Principal mapper{"mapper", "acme", static_cast<uint32_t>(Permission::kMapWrite) | static_cast<uint32_t>(Permission::kMapRead)};
  ASSERT_TRUE(manager_->load_map(mapper, stored, "auth").ok());
  const v1::FusionMap stored_proto = msgs::to_proto(stored);

  using Call = std::function<grpc::Status(grpc::ClientContext&)>;
  v1::SessionId session;
  session.set_id(session_id_);
  v1::MapRequest session_map;
  session_map.set_session_id(session_id_);
  struct Rpc {
    std::vector<std::string> permissions;
    Call call;
  };
  const std::map<std::string, Rpc> rpcs = {
      {"StreamImu", {{"fusion:session:write", "fusion:session:read"}, [&](grpc::ClientContext& c) { return close_stream(stub_->StreamImu(&c)); }}},
      {"StreamPointCloud", {{"fusion:session:write", "fusion:session:read"}, [&](grpc::ClientContext& c) { return close_stream(stub_->StreamPointCloud(&c)); }}},
      {"StreamImage", {{"fusion:session:write", "fusion:session:read"}, [&](grpc::ClientContext& c) { return close_stream(stub_->StreamImage(&c)); }}},
      {"StreamGnss", {{"fusion:session:write", "fusion:session:read"}, [&](grpc::ClientContext& c) { return close_stream(stub_->StreamGnss(&c)); }}},
      {"StreamRadar", {{"fusion:session:write", "fusion:session:read"}, [&](grpc::ClientContext& c) { return close_stream(stub_->StreamRadar(&c)); }}},
      {"StreamRange", {{"fusion:session:write", "fusion:session:read"}, [&](grpc::ClientContext& c) { return close_stream(stub_->StreamRange(&c)); }}},
      {"StreamDetections", {{"fusion:session:write", "fusion:session:read"}, [&](grpc::ClientContext& c) { return close_stream(stub_->StreamDetections(&c)); }}},
      {"StreamWheelOdometry", {{"fusion:session:write", "fusion:session:read"}, [&](grpc::ClientContext& c) { return close_stream(stub_->StreamWheelOdometry(&c)); }}},
      {"SubscribePose", {{"fusion:session:read"}, [&](grpc::ClientContext& c) { return drain(stub_->SubscribePose(&c, session)); }}},
      {"SubscribeKeyframes", {{"fusion:session:read"}, [&](grpc::ClientContext& c) { return drain(stub_->SubscribeKeyframes(&c, session)); }}},
      {"SubscribeMap", {{"fusion:map:read"}, [&](grpc::ClientContext& c) { return drain(stub_->SubscribeMap(&c, session)); }}},
      {"GetMap", {{"fusion:map:read"}, [&](grpc::ClientContext& c) {
                    v1::FusionMap map;
                    return stub_->GetMap(&c, session_map, &map);
                  }}},
      {"LoadMap", {{"fusion:map:write"}, [&](grpc::ClientContext& c) {
                     v1::LoadMapResponse response;
                     return stub_->LoadMap(&c, stored_proto, &response);
                   }}},
  };
  const google::protobuf::ServiceDescriptor* service =
      google::protobuf::DescriptorPool::generated_pool()->FindServiceByName(v1::FusionService::service_full_name());
  ASSERT_NE(service, nullptr);
  ASSERT_EQ(static_cast<std::size_t>(service->method_count()), rpcs.size());

  // The acme tokens of service_fixtures.hpp and their permissions (fusion:admin grants all).
  const std::vector<std::pair<const char*, std::set<std::string>>> acme_tokens = {
      {"acme-robot-secret-0001", {"fusion:session:write", "fusion:session:read", "fusion:map:read"}},
      {"acme-viewer-secret-0002", {"fusion:session:read"}},
      {"acme-mapper-secret-00006", {"fusion:map:read", "fusion:map:write"}},
      {"acme-admin-secret-00003", {"fusion:admin"}}};
  const auto call = [&](const Rpc& rpc, const std::string& token) {
    grpc::ClientContext context;
    prepare(context, token, session_id_);
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(300));
    return rpc.call(context).error_code();
  };
  for (int i = 0; i < service->method_count(); ++i) {
    const std::string name = service->method(i)->name();
    SCOPED_TRACE(name);
    ASSERT_EQ(rpcs.count(name), 1U) << "list the new RPC with its permission";
    const Rpc& rpc = rpcs.at(name);
    EXPECT_EQ(call(rpc, ""), grpc::StatusCode::UNAUTHENTICATED);
    EXPECT_EQ(call(rpc, "not-a-token-of-this-server"), grpc::StatusCode::UNAUTHENTICATED);
    EXPECT_EQ(call(rpc, "globex-admin-secret-0005"), grpc::StatusCode::PERMISSION_DENIED);
    for (const auto& [token, permissions] : acme_tokens) {
      const bool may = std::all_of(rpc.permissions.begin(), rpc.permissions.end(), [&](const std::string& needed) {
        return permissions.count(needed) != 0 || permissions.count("fusion:admin") != 0;
      });
      const grpc::StatusCode code = call(rpc, token);
      if (may) {
        EXPECT_NE(code, grpc::StatusCode::UNAUTHENTICATED) << token;
        EXPECT_NE(code, grpc::StatusCode::PERMISSION_DENIED) << token;
      } else {
        EXPECT_EQ(code, grpc::StatusCode::PERMISSION_DENIED) << token;
      }
    }
  }
}

}  // namespace
}  // namespace hanzo::fusion::service
