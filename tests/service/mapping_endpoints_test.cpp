// The map and loop-closure side of the server: a session streaming IMU + OS1-64 sweeps of the
// simulated urban_vehicle drive builds a map; REST serves it (?format=fmap|pcd|ply|json) and
// takes manual loop closures; gRPC serves GetMap, SubscribeMap and SubscribeKeyframes. Bad
// requests and missing permissions get the documented errors and leave the session intact.

#include <thread>

#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/maps/label_export.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/msgs/map_convert.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/pipeline/session_merge.hpp"
#include "hanzo/fusion/service/fusion_client.hpp"
#include "hanzo/fusion/service/grpc_server.hpp"
#include "hanzo/fusion/service/rest_server.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "hanzo/fusion/v1/service.grpc.pb.h"
#include "service_fixtures.hpp"
// Last: httplib pulls in <resolv.h>, whose `_res` macro breaks Eigen headers included after it.
#include <httplib.h>

namespace hanzo::fusion::service {
namespace {

using ::testing::HasSubstr;
using nlohmann::json;

constexpr const char* kRobotToken = "acme-robot-secret-0001";    // session read/write, map read
constexpr const char* kViewerToken = "acme-viewer-secret-0002";  // session read only
constexpr const char* kGlobexToken = "globex-robot-secret-0004";
constexpr const char* kAdminToken = "acme-admin-secret-00003";         // everything in acme (map:write too)
constexpr const char* kGlobexAdminToken = "globex-admin-secret-0005";
constexpr const char* kMapperToken = "acme-mapper-secret-00006";       // map read/write only
const Principal kStreamer{"robot", "acme", static_cast<uint32_t>(Permission::kSessionWrite) | static_cast<uint32_t>(Permission::kSessionRead)};

using testing::Recording;
using testing::urban_recording;

class MappingEndpointsTest : public ::testing::Test {
 protected:
  // A FusionClient's configuration for this fixture's servers, as the robot.
  FusionClientConfig client_config() const {
    FusionClientConfig config;
    config.rest_url = "http://127.0.0.1:" + std::to_string(rest_->port());
    config.grpc_address = "127.0.0.1:" + std::to_string(grpc_->port());
    config.token = kRobotToken;
    return config;
  }
  void SetUp() override {
    dir_ = testing::scratch_dir("-server");
    auto storage = open_storage("sqlite://" + (dir_ / "fusion.db").string());
    ASSERT_TRUE(storage.ok());
    metrics_ = std::make_shared<MetricsRegistry>();
    SessionManagerConfig manager_config;
    manager_config.map_directory = (dir_ / "maps").string();
    manager_config.map_save_interval = std::chrono::seconds(0);  // saved when asked (and at the end)
    manager_config.map_keep_versions = 2;
    manager_ = std::move(SessionManager::create(manager_config, std::move(storage).value(), metrics_)).value();
    auto tokens = TokenStore::parse(testing::kTokensYaml, "tokens.yaml");
    ASSERT_TRUE(tokens.ok());
    auto shared_tokens = std::make_shared<TokenStore>(std::move(tokens).value());
    RestServerConfig rest_config;
    rest_config.bind_address = "127.0.0.1";
    rest_config.port = 0;
    rest_ = std::move(RestServer::create(rest_config, *manager_, shared_tokens, metrics_)).value();
    ASSERT_TRUE(rest_->start().ok());
    GrpcServerConfig grpc_config;
    grpc_config.bind_address = "127.0.0.1";
    grpc_config.port = 0;
    grpc_ = std::move(GrpcServer::create(grpc_config, *manager_, shared_tokens, metrics_)).value();
    ASSERT_TRUE(grpc_->start().ok());
    grpc::ChannelArguments arguments;
    arguments.SetMaxReceiveMessageSize(256 << 20);  // maps are larger than gRPC's 4 MB default
    stub_ = v1::FusionService::NewStub(grpc::CreateCustomChannel("127.0.0.1:" + std::to_string(grpc_->port()),
                                                                 grpc::InsecureChannelCredentials(), arguments));
    const Recording& recording = urban_recording();
    session_id_ = manager_->create_session(kStreamer, {"urban", recording.config_yaml, recording.calibration_yaml}).value().id;
  }

  void stream_recording() {
    for (const testing::TimedMessage& message : urban_recording().messages) {
      ASSERT_TRUE(manager_->push(kStreamer, session_id_, message.sensor, message.message).ok());
    }
  }
  httplib::Client client() const {
    httplib::Client http("127.0.0.1", rest_->port());
    http.set_read_timeout(300, 0);  // generous: relocalization under ThreadSanitizer takes minutes
    return http;
  }
  static httplib::Headers bearer(const std::string& token) { return {{"Authorization", "Bearer " + token}}; }
  static json error_of(const httplib::Result& response) {
    EXPECT_TRUE(response);
    if (!response) return {};
    const json body = json::parse(response->body);
    EXPECT_TRUE(body.contains("error")) << response->body;
    return body.value("error", json::object());
  }
  static void prepare(grpc::ClientContext& context, const std::string& token) {
    if (!token.empty()) context.AddMetadata("authorization", "Bearer " + token);
  }

  std::filesystem::path dir_;  // the server's data: fusion.db, maps/
  std::shared_ptr<MetricsRegistry> metrics_;
  std::unique_ptr<SessionManager> manager_;
  std::unique_ptr<RestServer> rest_;
  std::unique_ptr<GrpcServer> grpc_;
  std::unique_ptr<v1::FusionService::Stub> stub_;
  std::string session_id_;
};

TEST_F(MappingEndpointsTest, RestServesTheMapInEveryFormatAndTakesLoopClosures) {
  const std::string path = "/v1/sessions/" + session_id_;
  // No map before the LiDAR has mapped anything.
  auto empty = client().Get(path + "/map?format=json", bearer(kRobotToken));
  ASSERT_TRUE(empty);
  EXPECT_EQ(empty->status, 404) << empty->body;
  stream_recording();

  const SessionInfo info = manager_->session_info(kStreamer, session_id_).value();
  EXPECT_GT(info.mapping.scans_registered, 60U);
  EXPECT_GT(info.mapping.map_keyframes, 3U);
  auto state = client().Get(path, bearer(kViewerToken));
  ASSERT_TRUE(state && state->status == 200);
  EXPECT_EQ(json::parse(state->body)["mapping"]["map_keyframes"], info.mapping.map_keyframes);

  auto summary = client().Get(path + "/map?format=json", bearer(kRobotToken));
  ASSERT_TRUE(summary);
  ASSERT_EQ(summary->status, 200) << summary->body;
  const json map_json = json::parse(summary->body);
  EXPECT_EQ(map_json["map_id"], session_id_);
  const std::size_t points = map_json["layers"]["points"]["count"];
  EXPECT_GT(points, 1000U);
  EXPECT_TRUE(map_json["layers"].contains("occupancy"));

  // The default: the FusionMap file, which parses back to the same map.
  auto fmap = client().Get(path + "/map", bearer(kRobotToken));
  ASSERT_TRUE(fmap && fmap->status == 200);
  auto parsed = maps::parse_fusion_map(fmap->body);
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  EXPECT_EQ(parsed->map_id, session_id_);
  ASSERT_TRUE(parsed->points.has_value());
  EXPECT_EQ(parsed->points->points.size(), points);
  EXPECT_THAT(parsed->sensor_configuration, HasSubstr("fusion:"));
  EXPECT_EQ(parsed->provenance.algorithm, "pipeline/session");
  for (const char* format : {"pcd", "ply"}) {
    auto cloud_response = client().Get(path + "/map?format=" + format, bearer(kRobotToken));
    ASSERT_TRUE(cloud_response && cloud_response->status == 200);
    EXPECT_THAT(cloud_response->get_header_value("Content-Disposition"), HasSubstr(std::string(".") + format));
    const std::filesystem::path file = testing::scratch_dir(format) / (std::string("map.") + format);
    std::ofstream(file, std::ios::binary) << cloud_response->body;
    auto cloud = cloud::read_cloud(file.string());
    ASSERT_TRUE(cloud.ok()) << cloud.error().message;
    EXPECT_EQ(cloud->size(), points);
  }
  EXPECT_EQ(error_of(client().Get(path + "/map?format=las", bearer(kRobotToken)))["field"], "format");
  // Permissions: map:read is needed, and the session's organization.
  auto viewer = client().Get(path + "/map", bearer(kViewerToken));
  ASSERT_TRUE(viewer);
  EXPECT_EQ(viewer->status, 403);
  auto globex = client().Get(path + "/map", bearer(kGlobexToken));
  ASSERT_TRUE(globex);
  EXPECT_EQ(globex->status, 403);
  auto anonymous = client().Get(path + "/map");
  ASSERT_TRUE(anonymous);
  EXPECT_EQ(anonymous->status, 401);
  auto unknown = client().Get("/v1/sessions/no-such-session/map", bearer(kRobotToken));
  ASSERT_TRUE(unknown);
  EXPECT_EQ(unknown->status, 404);

  // Loop closures: bad requests are refused with the field at fault.
  const auto post = [&](const std::string& body, const std::string& token = kRobotToken) {
    return client().Post(path + "/loop-closure", bearer(token), body, "application/json");
  };
  EXPECT_EQ(error_of(post("{not json"))["field"], "body");
  EXPECT_EQ(error_of(post(R"({"from_keyframe": -1, "to_keyframe": 2})"))["field"], "from_keyframe");
  EXPECT_EQ(error_of(post(R"({"from_keyframe": 1, "to_keyframe": 2, "relative_pose": {"position": [1, 2]}})"))["field"],
            "relative_pose.position");
  EXPECT_EQ(error_of(post(R"({"from_keyframe": 1, "to_keyframe": 2, "relative_pose": {"position": [1, 2, 3], "orientation_wxyz": [2, 0, 0, 0]}})"))["field"],
            "relative_pose.orientation_wxyz");
  EXPECT_EQ(error_of(post(R"({"from_keyframe": 1, "to_keyframe": 2, "covariance": [1, 2]})"))["field"], "covariance");
  EXPECT_EQ(error_of(post(R"({"from_keyframe": 1, "colour": "red"})"))["field"], "colour");
  auto half = post(R"({"from_keyframe": 1})");
  ASSERT_TRUE(half);
  EXPECT_EQ(half->status, 400) << half->body;
  auto missing = post(R"({"from_keyframe": 999999, "to_keyframe": 2, "relative_pose": {"position": [0, 0, 0]}})");
  ASSERT_TRUE(missing);
  EXPECT_EQ(missing->status, 404) << missing->body;
  EXPECT_THAT(missing->body, HasSubstr("999999"));
  auto read_only = post("{}", kViewerToken);
  ASSERT_TRUE(read_only);
  EXPECT_EQ(read_only->status, 403);
  EXPECT_EQ(manager_->session_info(kStreamer, session_id_).value().mapping.manual_loop_closures, 0U);

  // A closure given with a relative pose and a loose covariance is taken.
  const SessionInfo after_errors = manager_->session_info(kStreamer, session_id_).value();
  auto closed = post(R"({"from_keyframe": 3, "to_keyframe": 4, "relative_pose": {"position": [0, 0, 0]}, "covariance": [)"
                     "1,0,0,0,0,0, 0,1,0,0,0,0, 0,0,1,0,0,0, 0,0,0,1,0,0, 0,0,0,0,1,0, 0,0,0,0,0,1]}");
  ASSERT_TRUE(closed);
  ASSERT_EQ(closed->status, 200) << closed->body;
  const json outcome = json::parse(closed->body);
  EXPECT_EQ(outcome["from_keyframe"], 3);
  EXPECT_EQ(outcome["registered"], false);
  EXPECT_EQ(manager_->session_info(kStreamer, session_id_).value().mapping.manual_loop_closures, 1U);
  EXPECT_EQ(after_errors.summary.poses, manager_->session_info(kStreamer, session_id_).value().summary.poses);
}

TEST_F(MappingEndpointsTest, GrpcServesTheMapAndStreamsKeyframesAndMapUpdates) {
  grpc::ClientContext keyframe_context, map_context;
  prepare(keyframe_context, kViewerToken);
  prepare(map_context, kRobotToken);
  v1::SessionId session;
  session.set_id(session_id_);
  auto keyframes = stub_->SubscribeKeyframes(&keyframe_context, session);
  auto updates = stub_->SubscribeMap(&map_context, session);
  std::vector<v1::Keyframe> received_keyframes;
  std::vector<v1::MapUpdate> received_updates;
  std::thread keyframe_reader([&] {
    v1::Keyframe keyframe;
    while (keyframes->Read(&keyframe)) received_keyframes.push_back(keyframe);
  });
  std::thread update_reader([&] {
    v1::MapUpdate update;
    while (updates->Read(&update)) received_updates.push_back(update);
  });
  // The subscriptions are registered asynchronously, once the calls reach the server.
  for (int attempt = 0; attempt < 3000; ++attempt) {
    const SessionInfo subscribed = manager_->session_info(kStreamer, session_id_).value();
    if (subscribed.keyframe_subscribers == 1 && subscribed.map_subscribers == 1) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(manager_->session_info(kStreamer, session_id_).value().keyframe_subscribers, 1u);
  EXPECT_EQ(manager_->session_info(kStreamer, session_id_).value().map_subscribers, 1u);
  stream_recording();
  const SessionInfo info = manager_->session_info(kStreamer, session_id_).value();
  ASSERT_TRUE(manager_->end_session(kStreamer, session_id_).ok());  // closes the subscriptions
  keyframe_reader.join();
  update_reader.join();
  EXPECT_EQ(received_keyframes.size(), info.summary.keyframes);
  ASSERT_FALSE(received_updates.empty());
  EXPECT_GE(received_updates.size(), info.mapping.map_keyframes);  // plus replacements after corrections
  EXPECT_EQ(received_updates.front().map_id(), session_id_);
  EXPECT_GT(received_updates.front().added_points().points_size(), 100);

  // GetMap: the ended session's final map.
  grpc::ClientContext get_context;
  prepare(get_context, kRobotToken);
  v1::MapRequest request;
  request.set_session_id(session_id_);
  v1::FusionMap map;
  const grpc::Status got = stub_->GetMap(&get_context, request, &map);
  ASSERT_TRUE(got.ok()) << got.error_message();
  auto decoded = msgs::from_proto(map);
  ASSERT_TRUE(decoded.ok()) << decoded.error().message;
  ASSERT_TRUE(decoded->points.has_value());
  EXPECT_GT(decoded->points->points.size(), 1000U);
  EXPECT_EQ(decoded->version, 1U);  // the ended session's final map, read from the map store
  EXPECT_EQ(decoded->map_id, session_id_);
  // Errors: a version that is not kept, a map that is not the session's, no token, no map:read.
  const auto get_map = [&](const std::string& token, uint64_t version, const std::string& map_id) {
    grpc::ClientContext context;
    prepare(context, token);
    v1::MapRequest bad = request;
    bad.set_version(version);
    bad.set_map_id(map_id);
    v1::FusionMap ignored;
    return stub_->GetMap(&context, bad, &ignored).error_code();
  };
  EXPECT_EQ(get_map(kRobotToken, info.mapping.map_version + 7, ""), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(get_map(kRobotToken, 0, "another-map"), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(get_map("", 0, ""), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(get_map(kViewerToken, 0, ""), grpc::StatusCode::PERMISSION_DENIED);
}

// Stored maps: the session's map is saved as versions; a client loads a map (REST and gRPC),
// reads its versions back in every format, and relocalizes a second session in it.
TEST_F(MappingEndpointsTest, StoresMapVersionsLoadsMapsAndRelocalizesASessionInThem) {
  const auto get = [&](const std::string& path, const std::string& token) { return client().Get(path, bearer(token)); };
  auto none = get("/v1/maps", kRobotToken);
  ASSERT_TRUE(none && none->status == 200) << (none ? none->body : "");
  EXPECT_TRUE(json::parse(none->body)["maps"].empty());
  stream_recording();
  ASSERT_TRUE(manager_->save_session_maps().ok());
  ASSERT_TRUE(manager_->save_session_maps().ok());  // unchanged: no new version
  auto listed = get("/v1/maps", kRobotToken);
  ASSERT_TRUE(listed && listed->status == 200);
  json maps_json = json::parse(listed->body)["maps"];
  ASSERT_EQ(maps_json.size(), 1U) << listed->body;
  EXPECT_EQ(maps_json[0]["map_id"], session_id_);
  EXPECT_EQ(maps_json[0]["session_id"], session_id_);
  EXPECT_EQ(maps_json[0]["versions"].size(), 1U);

  // A known map: the session's map moved 40 m and turned 2 rad, loaded by a client.
  const Principal admin{"admin", "acme", static_cast<uint32_t>(Permission::kAdmin)};
  auto session_map = manager_->map(admin, session_id_);
  ASSERT_TRUE(session_map.ok()) << session_map.error().message;
  msgs::FusionMap known = std::move(session_map).value();
  const SE3 T_known_world(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 2.0), Eigen::Vector3d(40.0, 25.0, -1.0));
  for (Eigen::Vector3f& point : known.points->points) point = (T_known_world * point.cast<double>()).cast<float>();
  known.occupancy.reset();
  known.map_id = "street-survey";
  known.version = 0;
  auto serialized = maps::serialize_fusion_map(known);
  ASSERT_TRUE(serialized.ok()) << serialized.error().message;
  const std::string known_file = std::move(serialized).value();
  const auto post_map = [&](const std::string& body, const std::string& token) {
    return client().Post("/v1/maps?name=street", bearer(token), body, "application/octet-stream");
  };
  auto refused = post_map(known_file, kRobotToken);  // map:read only
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 403);
  EXPECT_EQ(error_of(post_map("not a map", kAdminToken))["field"], "body");
  auto loaded = post_map(known_file, kAdminToken);
  ASSERT_TRUE(loaded);
  ASSERT_EQ(loaded->status, 201) << loaded->body;
  const std::string known_id = json::parse(loaded->body)["map_id"];
  EXPECT_EQ(known_id, "street-survey");
  EXPECT_EQ(json::parse(loaded->body)["version"], 1);
  // A second version of it over gRPC (LoadMap), the first one as its parent.
  {
    grpc::ClientContext context;
    prepare(context, kAdminToken);
    known.map_id = known_id;
    known.version = 1;
    v1::LoadMapResponse response;
    const grpc::Status status = stub_->LoadMap(&context, msgs::to_proto(known), &response);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_EQ(response.map_id(), known_id);
    EXPECT_EQ(response.version(), 2U);
    grpc::ClientContext other;
    prepare(other, kGlobexAdminToken);
    EXPECT_EQ(stub_->LoadMap(&other, msgs::to_proto(known), &response).error_code(), grpc::StatusCode::PERMISSION_DENIED);
    grpc::ClientContext invalid;
    prepare(invalid, kAdminToken);
    v1::FusionMap broken = msgs::to_proto(known);
    broken.set_format_version(99);
    EXPECT_EQ(stub_->LoadMap(&invalid, broken, &response).error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  }
  auto versions = get("/v1/maps/" + known_id + "?format=json", kRobotToken);
  ASSERT_TRUE(versions && versions->status == 200) << (versions ? versions->body : "");
  const json versions_json = json::parse(versions->body);
  EXPECT_EQ(versions_json["name"], "street");
  EXPECT_TRUE(versions_json["session_id"].is_null());
  ASSERT_EQ(versions_json["versions"].size(), 2U);
  EXPECT_EQ(versions_json["versions"][1]["parent_version"], 1);
  auto first = get("/v1/maps/" + known_id + "?version=1", kRobotToken);
  ASSERT_TRUE(first && first->status == 200);
  auto parsed = maps::parse_fusion_map(first->body);
  ASSERT_TRUE(parsed.ok()) << parsed.error().message;
  EXPECT_EQ(parsed->points->points.size(), known.points->points.size());
  EXPECT_EQ(parsed->points->points.front(), known.points->points.front());
  auto pcd = get("/v1/maps/" + known_id + "?format=pcd", kRobotToken);
  ASSERT_TRUE(pcd && pcd->status == 200);
  // The points by semantic label (the session labels its map's points); no segmentation classes.
  ASSERT_FALSE(known.points->labels.empty());
  auto labels = get("/v1/maps/" + known_id + "?format=labels", kRobotToken);
  ASSERT_TRUE(labels && labels->status == 200);
  EXPECT_EQ(labels->body, maps::labelled_points_ply(*known.points).value());
  auto classes = get("/v1/maps/" + known_id + "?format=classes", kRobotToken);
  ASSERT_TRUE(classes);
  EXPECT_EQ(classes->status, 404);
  EXPECT_NE(classes->body.find("no segmentation classes"), std::string::npos);
  // Temporal queries: the version current at a time, by its creation time.
  const int64_t second_created = versions_json["versions"][1]["created_ns"];
  const int64_t first_created = versions_json["versions"][0]["created_ns"];
  auto then = get(fmt::format("/v1/maps/{}?format=json&at_ns={}", known_id, second_created), kRobotToken);
  ASSERT_TRUE(then && then->status == 200);
  auto at_first = get(fmt::format("/v1/maps/{}?at_ns={}", known_id, first_created), kRobotToken);
  ASSERT_TRUE(at_first && at_first->status == 200);
  EXPECT_EQ(maps::parse_fusion_map(at_first->body)->version, first_created < second_created ? 1u : 2u);
  EXPECT_EQ(get(fmt::format("/v1/maps/{}?at_ns={}", known_id, second_created), kRobotToken)->body, get("/v1/maps/" + known_id + "?version=2", kRobotToken)->body);
  EXPECT_EQ(get(fmt::format("/v1/maps/{}?at_ns={}", known_id, first_created - 1), kRobotToken)->status, 404);
  EXPECT_EQ(get(fmt::format("/v1/maps/{}?at_ns=5&version=1", known_id), kRobotToken)->status, 400);
  EXPECT_EQ(get("/v1/maps/" + known_id + "?version=9", kRobotToken)->status, 404);
  EXPECT_EQ(get("/v1/maps/" + known_id + "?version=x", kRobotToken)->status, 400);
  EXPECT_EQ(get("/v1/maps/no-such-map", kRobotToken)->status, 404);
  EXPECT_EQ(get("/v1/maps/" + known_id, kGlobexAdminToken)->status, 403);  // another organization's
  EXPECT_EQ(get("/v1/maps/" + known_id, kViewerToken)->status, 403);      // no map:read
  EXPECT_EQ(get("/v1/maps/" + known_id, "")->status, 401);
  {
    grpc::ClientContext context;
    prepare(context, kRobotToken);
    v1::MapRequest request;
    request.set_map_id(known_id);
    request.set_version(1);
    v1::FusionMap map;
    const grpc::Status status = stub_->GetMap(&context, request, &map);
    ASSERT_TRUE(status.ok()) << status.error_message();
    EXPECT_EQ(map.version(), 1U);
  }

  // Relocalization: a second session on the same drive, localized in the known map.
  const Recording& recording = urban_recording();
  const std::string second = manager_->create_session(kStreamer, {"second", recording.config_yaml, recording.calibration_yaml}).value().id;
  const auto relocalize = [&](const std::string& session, const std::string& body, const std::string& token = kRobotToken) {
    return client().Post("/v1/sessions/" + session + "/relocalize", bearer(token), body, "application/json");
  };
  auto early = relocalize(second, R"({"map_id": ")" + known_id + "\"}");
  ASSERT_TRUE(early);
  EXPECT_EQ(early->status, 409) << early->body;  // nothing mapped yet
  for (const testing::TimedMessage& message : recording.messages) ASSERT_TRUE(manager_->push(kStreamer, second, message.sensor, message.message).ok());
  EXPECT_EQ(error_of(relocalize(second, "{}"))["field"], "map_id");
  EXPECT_EQ(error_of(relocalize(second, R"({"map_id": "x", "linear_window_m": -1})"))["field"], "linear_window_m");
  EXPECT_EQ(error_of(relocalize(second, R"({"map_id": "x", "initial_pose": {"position": [1, 2]}})"))["field"], "initial_pose.position");
  EXPECT_EQ(relocalize(second, R"({"map_id": "no-such-map"})")->status, 404);
  EXPECT_EQ(relocalize(second, R"({"map_id": ")" + known_id + "\"}", kViewerToken)->status, 403);
  EXPECT_THAT(error_of(relocalize(second, R"({"map_id": ")" + known_id + R"(", "sensor": "camera"})"))["message"].get<std::string>(),
              HasSubstr("no visual landmark layer"));
  EXPECT_EQ(error_of(relocalize(second, R"({"map_id": ")" + known_id + R"(", "sensor": "radar"})"))["field"], "sensor");
  EXPECT_EQ(manager_->session_info(kStreamer, second).value().mapping.relocalizations, 0U);
  auto relocalized = relocalize(second, R"({"map_id": ")" + known_id + R"(", "version": 1})");
  ASSERT_TRUE(relocalized);
  ASSERT_EQ(relocalized->status, 200) << relocalized->body;
  const json outcome = json::parse(relocalized->body);
  EXPECT_EQ(outcome["version"], 1);
  EXPECT_EQ(outcome["global_search"], true);
  EXPECT_EQ(outcome["sensor"], "lidar");
  const std::vector<double> position = outcome["T_map_world"]["position"];
  EXPECT_LT((Eigen::Vector3d(position[0], position[1], position[2]) - T_known_world.translation()).norm(), 0.2) << relocalized->body;
  EXPECT_EQ(manager_->session_info(kStreamer, second).value().mapping.relocalizations, 1U);
  // Its poses are in the known map's frame now.
  const msgs::PoseEstimate first_pose = manager_->current_pose(kStreamer, session_id_).value();
  const msgs::PoseEstimate second_pose = manager_->current_pose(kStreamer, second).value();
  EXPECT_LT((second_pose.T_world_body.position - T_known_world * first_pose.T_world_body.position).norm(), 0.3);

  // After a restart the ended session's map and the loaded map are read back from the store.
  ASSERT_TRUE(manager_->end_session(kStreamer, session_id_).ok());
  rest_.reset();
  grpc_.reset();
  manager_.reset();
  auto storage = open_storage("sqlite://" + (dir_ / "fusion.db").string());
  ASSERT_TRUE(storage.ok());
  SessionManagerConfig config;
  config.map_directory = (dir_ / "maps").string();
  auto restarted = SessionManager::create(config, std::move(storage).value(), metrics_);
  ASSERT_TRUE(restarted.ok()) << restarted.error().message;
  auto final_map = restarted.value()->map(admin, session_id_);
  ASSERT_TRUE(final_map.ok()) << final_map.error().message;
  EXPECT_EQ(final_map->points->points.size(), known.points->points.size());
  auto all = restarted.value()->list_maps(admin);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->size(), 3U);  // both sessions' maps and the loaded one
  EXPECT_EQ(restarted.value()->stored_map(admin, known_id).value().version, 2U);
}

// A merged map (pipeline/session_merge.hpp) of two sessions' maps, one of them in another frame,
// loaded by a client; a new session on the same streets starts localized in it.
TEST_F(MappingEndpointsTest, ASessionStartsLocalizedInAMergedMap) {
  stream_recording();
  const Principal admin{"admin", "acme", static_cast<uint32_t>(Permission::kAdmin)};
  msgs::FusionMap session_map = manager_->map(admin, session_id_).value();
  ASSERT_TRUE(session_map.lidar_keyframes) << "sessions keep their LiDAR keyframes in their maps";
  // The first survey's frame: 40 m away and turned 2 rad from the session's world.
  const SE3 T_survey_world(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 2.0), Eigen::Vector3d(40.0, 25.0, -1.0));
  msgs::FusionMap survey = session_map;
  survey.map_id = "survey";
  for (msgs::LidarKeyframe& keyframe : survey.lidar_keyframes->keyframes) {
    keyframe.T_world_lidar = msgs::Pose::from_se3(T_survey_world * keyframe.T_world_lidar.to_se3());
  }
  for (Eigen::Vector3f& point : survey.points->points) point = (T_survey_world * point.cast<double>()).cast<float>();
  survey.occupancy.reset();
  session_map.map_id = "session";
  Result<pipeline::SessionMergeResult> merge = pipeline::merge_sessions({survey, session_map});
  ASSERT_TRUE(merge.ok()) << merge.error().message;
  pipeline::SessionMergeResult& merged = merge.value();
  ASSERT_EQ(merged.joins.size(), 1U);
  EXPECT_LT((merged.joins[0].T_joined_map.translation() - T_survey_world.translation()).norm(), 0.05);
  merged.merged.map_id = "merged-streets";
  auto loaded = client().Post("/v1/maps?name=streets", bearer(kAdminToken), maps::serialize_fusion_map(merged.merged).value(), "application/octet-stream");
  ASSERT_TRUE(loaded);
  ASSERT_EQ(loaded->status, 201) << loaded->body;
  const std::string map_id = json::parse(loaded->body)["map_id"];

  // A new session's first half, relocalized in the merged map, then the rest of the drive.
  const Recording& recording = urban_recording();
  const std::string fresh = manager_->create_session(kStreamer, {"fresh", recording.config_yaml, recording.calibration_yaml}).value().id;
  const std::size_t half = recording.messages.size() / 2;
  for (std::size_t i = 0; i < half; ++i) {
    ASSERT_TRUE(manager_->push(kStreamer, fresh, recording.messages[i].sensor, recording.messages[i].message).ok());
  }
  auto relocalized = client().Post("/v1/sessions/" + fresh + "/relocalize", bearer(kRobotToken), R"({"map_id": ")" + map_id + "\"}", "application/json");
  ASSERT_TRUE(relocalized);
  ASSERT_EQ(relocalized->status, 200) << relocalized->body;
  const std::vector<double> position = json::parse(relocalized->body)["T_map_world"]["position"];
  EXPECT_LT((Eigen::Vector3d(position[0], position[1], position[2]) - T_survey_world.translation()).norm(), 0.2) << relocalized->body;
  for (std::size_t i = half; i < recording.messages.size(); ++i) {
    ASSERT_TRUE(manager_->push(kStreamer, fresh, recording.messages[i].sensor, recording.messages[i].message).ok());
  }
  // Where the first session ended, in the merged map's frame.
  const msgs::PoseEstimate first_pose = manager_->current_pose(kStreamer, session_id_).value();
  const msgs::PoseEstimate fresh_pose = manager_->current_pose(kStreamer, fresh).value();
  EXPECT_LT((fresh_pose.T_world_body.position - T_survey_world * first_pose.T_world_body.position).norm(), 0.3);
}

TEST_F(MappingEndpointsTest, OldAutosavesArePrunedAndMapsOrVersionsCanBeDeleted) {
  // Three saves of the session's map while it grows; retention keeps the newest two.
  const auto& messages = urban_recording().messages;
  for (std::size_t part = 1; part <= 3; ++part) {
    for (std::size_t i = (part - 1) * messages.size() / 3; i < part * messages.size() / 3; ++i) {
      ASSERT_TRUE(manager_->push(kStreamer, session_id_, messages[i].sensor, messages[i].message).ok());
    }
    ASSERT_TRUE(manager_->save_session_maps().ok());
  }
  const Principal admin{"admin", "acme", static_cast<uint32_t>(Permission::kAdmin)};
  auto stored = manager_->stored_map_info(admin, session_id_);
  ASSERT_TRUE(stored.ok()) << stored.error().message;
  ASSERT_EQ(stored->versions.size(), 2U);
  EXPECT_EQ(stored->versions[0].version, 2U);
  EXPECT_EQ(stored->versions[1].version, 3U);

  const auto remove = [&](const std::string& path, const std::string& token) { return client().Delete("/v1/maps/" + path, bearer(token)); };
  EXPECT_EQ(remove(session_id_, kAdminToken)->status, 409);  // the map of a running session
  EXPECT_THAT(error_of(remove(session_id_, kAdminToken))["message"].get<std::string>(), HasSubstr("end the session first"));
  EXPECT_EQ(remove(session_id_ + "?version=3", kAdminToken)->status, 409);  // the newest
  EXPECT_EQ(remove(session_id_ + "?version=1", kAdminToken)->status, 404);  // pruned already
  EXPECT_EQ(error_of(remove(session_id_ + "?version=0", kAdminToken))["field"], "version");
  EXPECT_EQ(remove(session_id_ + "?version=2", kRobotToken)->status, 403);  // map:read only
  auto version_deleted = remove(session_id_ + "?version=2", kMapperToken);
  ASSERT_TRUE(version_deleted);
  ASSERT_EQ(version_deleted->status, 200) << version_deleted->body;
  EXPECT_EQ(json::parse(version_deleted->body)["versions_deleted"], 1);
  EXPECT_EQ(client().Get("/v1/maps/" + session_id_ + "?version=2", bearer(kRobotToken))->status, 404);
  EXPECT_EQ(client().Get("/v1/maps/" + session_id_ + "?version=3", bearer(kRobotToken))->status, 200);

  // A loaded map with two versions goes at once; another organization cannot touch it.
  msgs::FusionMap yard;
  yard.map_id = "yard";
  yard.points = msgs::PointLayer{};
  yard.points->points = {Eigen::Vector3f(1.0F, 2.0F, 0.5F)};
  const std::string yard_file = maps::serialize_fusion_map(yard).value();
  for (int i = 0; i < 2; ++i) {
    ASSERT_EQ(client().Post("/v1/maps", bearer(kMapperToken), yard_file, "application/octet-stream")->status, 201);
  }
  EXPECT_EQ(remove("yard", kGlobexAdminToken)->status, 403);
  auto map_deleted = remove("yard", kMapperToken);
  ASSERT_TRUE(map_deleted);
  ASSERT_EQ(map_deleted->status, 200) << map_deleted->body;
  EXPECT_EQ(json::parse(map_deleted->body)["versions_deleted"], 2);
  EXPECT_EQ(client().Get("/v1/maps/yard?format=json", bearer(kRobotToken))->status, 404);
  EXPECT_EQ(remove("yard", kMapperToken)->status, 404);
  EXPECT_EQ(client().Post("/v1/maps", bearer(kMapperToken), yard_file, "application/octet-stream")->status, 201);  // the id again

  // Once the session ended its map can go too; the deletion survives a restart.
  ASSERT_TRUE(manager_->end_session(kStreamer, session_id_).ok());
  auto ended_deleted = remove(session_id_, kAdminToken);
  ASSERT_TRUE(ended_deleted);
  ASSERT_EQ(ended_deleted->status, 200) << ended_deleted->body;
  EXPECT_EQ(client().Get("/v1/maps/" + session_id_ + "?format=json", bearer(kRobotToken))->status, 404);
  rest_.reset();
  grpc_.reset();
  manager_.reset();
  SessionManagerConfig config;
  config.map_directory = (dir_ / "maps").string();
  auto restarted = SessionManager::create(config, open_storage("sqlite://" + (dir_ / "fusion.db").string()).value(), metrics_);
  ASSERT_TRUE(restarted.ok()) << restarted.error().message;
  auto left = restarted.value()->list_maps(admin);
  ASSERT_TRUE(left.ok());
  ASSERT_EQ(left->size(), 1U);
  EXPECT_EQ(left->front().record.map_id, "yard");
  EXPECT_EQ(left->front().versions.size(), 1U);
}

TEST_F(MappingEndpointsTest, FusionClientStreamsALogIntoANewSessionAndReportsServerErrors) {
  // The recording as a sensor log under the configuration's topics, with a pose-estimate topic
  // and a sensor topic no configured sensor reads: the client skips both.
  const std::string log = (testing::scratch_dir() / "urban.mcap").string();
  {
    io::SensorLogWriterConfig writer_config;
    writer_config.foxglove_channels = false;
    auto writer = io::SensorLogWriter::open(log, writer_config).value();
    for (const testing::TimedMessage& message : urban_recording().messages) {
      ASSERT_TRUE(writer->write("/sensors/" + message.sensor, message.message).ok());
    }
    ASSERT_TRUE(writer->write("/sensors/spare_imu", urban_recording().messages.front().message).ok());
    msgs::PoseEstimate estimate;
    estimate.timestamp = msgs::timestamp_of(urban_recording().messages.back().message);
    ASSERT_TRUE(writer->write("/estimate", estimate).ok());
    ASSERT_TRUE(writer->close().ok());
  }
  FusionClientConfig config = client_config();
  auto client = FusionClient::create(config).value();
  const Recording& recording = urban_recording();
  auto session_id = client->create_session("streamed", recording.config_yaml, recording.calibration_yaml);
  ASSERT_TRUE(session_id.ok()) << session_id.error().message;
  StreamOptions options;
  options.rate = 0.0;  // as fast as the server fuses
  // Under ThreadSanitizer a LiDAR sweep can take the server longer than the 10 s stall timeout.
  StreamOptions patient = options;
  patient.stall_timeout_s = 600.0;
  auto streamed = client->stream_log(log, session_id.value(), patient);
  ASSERT_TRUE(streamed.ok()) << streamed.error().message;
  EXPECT_EQ(streamed->messages_sent, recording.messages.size());
  EXPECT_EQ(streamed->accepted, recording.messages.size());
  EXPECT_EQ(streamed->skipped_by_topic.at("/estimate"), 1U);
  EXPECT_EQ(streamed->skipped_by_topic.at("/sensors/spare_imu"), 1U);
  EXPECT_GT(streamed->poses_received, 1000U);
  ASSERT_TRUE(streamed->latest_pose.has_value());
  // Every message reached the session, none too late for it, and the LiDAR mapped.
  const Principal owner{"robot", "acme", static_cast<uint32_t>(Permission::kSessionRead)};
  const SessionInfo info = manager_->session_info(owner, session_id.value()).value();
  for (const pipeline::SensorStatistics& sensor : info.summary.sensors) {
    EXPECT_EQ(sensor.received, streamed->sent_by_sensor.at(sensor.name)) << sensor.name;
    EXPECT_EQ(sensor.rejected.count(pipeline::Rejection::kTooLate), 0U) << sensor.name;
  }
  // (Streamed as fast as the server fuses, how many of the 110 sweeps after the alignment a
  // realtime session registers depends on the machine's load: 56 with other tests beside it.)
  EXPECT_GT(info.mapping.scans_registered, 40U);
  EXPECT_THAT(client->get("/v1/sessions/" + session_id.value()).value(), HasSubstr("\"map_keyframes\""));
  ASSERT_TRUE(client->end_session(session_id.value()).ok());

  // Topics mapped to a sensor the session does not have: sent, none accepted (said, not an error).
  auto second = client->create_session("misnamed", recording.config_yaml, recording.calibration_yaml);
  ASSERT_TRUE(second.ok()) << second.error().message;
  StreamOptions misnamed = options;
  misnamed.sensor_by_topic = {{"/sensors/imu", "sensors/imu"}};
  auto unaccepted = client->stream_log(log, second.value(), misnamed);
  ASSERT_TRUE(unaccepted.ok()) << unaccepted.error().message;
  EXPECT_GT(unaccepted->messages_sent, 1000U);
  EXPECT_EQ(unaccepted->accepted, 0U);
  EXPECT_TRUE(unaccepted->skipped_by_topic.contains("/sensors/lidar"));

  // Errors name what the server said, or the address that did not answer.
  auto ended = client->stream_log(log, session_id.value(), options);
  ASSERT_FALSE(ended.ok());
  EXPECT_THAT(ended.error().message, HasSubstr("ended"));
  auto unknown = client->stream_log(log, "no-such-session", options);
  ASSERT_FALSE(unknown.ok());
  EXPECT_THAT(unknown.error().message, HasSubstr("no-such-session"));
  config.token = "wrong-token-0000000000";
  auto intruder = FusionClient::create(config).value();
  auto refused = intruder->create_session("x", recording.config_yaml, "");
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused.error().message, HasSubstr("401"));
  EXPECT_FALSE(client->stream_log(log + ".missing", session_id.value(), options).ok());
  config.token = kRobotToken;
  config.rest_url = "http://127.0.0.1:1";
  auto nobody = FusionClient::create(config).value()->stream_log(log, session_id.value(), options);
  ASSERT_FALSE(nobody.ok());
  EXPECT_THAT(nobody.error().message, HasSubstr("http://127.0.0.1:1"));
  config.rest_url = "ftp://127.0.0.1";
  EXPECT_FALSE(FusionClient::create(config).ok());
}

// SessionStreams: messages a caller makes (a live driver) into a session, one stream per sensor:
// every message of the recording's first 5 s sent in time order is accepted, poses come back; a
// message for a sensor the session does not have is sent and not accepted.
TEST_F(MappingEndpointsTest, SessionStreamsSendACallersMessagesIntoASession) {
  auto client = FusionClient::create(client_config()).value();
  const Recording& recording = urban_recording();
  auto session_id = client->create_session("live", recording.config_yaml, recording.calibration_yaml);
  ASSERT_TRUE(session_id.ok()) << session_id.error().message;
  auto streams = client->open_streams(session_id.value());
  ASSERT_TRUE(streams.ok()) << streams.error().message;
  const Timestamp start = msgs::timestamp_of(recording.messages.front().message);
  uint64_t sent = 0;
  for (const testing::TimedMessage& message : recording.messages) {
    if ((msgs::timestamp_of(message.message) - start).seconds() > 5.0) break;
    ASSERT_TRUE((*streams)->send(message.sensor, message.message).ok());
    ++sent;
  }
  // A sensor the session does not have: sent, refused by the session (not accepted).
  ASSERT_TRUE((*streams)->send("no_such_sensor", recording.messages.front().message).ok());
  auto summary = (*streams)->finish();
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_EQ(summary->messages_sent, sent + 1);
  EXPECT_EQ(summary->accepted, sent);
  EXPECT_GT(summary->poses_received, 100U);
  ASSERT_TRUE(summary->latest_pose.has_value());
  EXPECT_FALSE(client->open_streams("no-such-session").ok());
  ASSERT_TRUE(client->end_session(session_id.value()).ok());
}

// A cameras-only session relocalized in a stored visual landmark map: the drone's stereo
// survey (8 s) stored as a map moved to a known place; a second session that starts 3 s into
// the same flight (its world: the body then) places its newest images in it through REST.
TEST_F(MappingEndpointsTest, RelocalizesACameraSessionInAStoredVisualLandmarkMap) {
  sim::Scenario scenario = sim::load_scenario("examples/scenarios/drone.yaml").value();
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& s) { return s.modality != config::SensorModality::kCamera; });
  scenario.duration = 8.0;
  scenario.num_threads = 0;
  const std::string config_yaml = config::to_yaml(sim::scenario_fusion_config(scenario));
  const std::string calibration_yaml = calib::to_yaml(sim::scenario_calibration(scenario));
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  std::vector<testing::TimedMessage> messages;
  ASSERT_TRUE(simulation->run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status {
    messages.push_back({sensor.name, std::move(message)});
    return ok_status();
  }).ok());
  auto created = manager_->create_session(kStreamer, {"survey", config_yaml, calibration_yaml});
  ASSERT_TRUE(created.ok()) << created.error().message;
  const std::string survey = created.value().id;
  for (const testing::TimedMessage& message : messages) ASSERT_TRUE(manager_->push(kStreamer, survey, message.sensor, message.message).ok());
  const Principal admin{"admin", "acme", static_cast<uint32_t>(Permission::kAdmin)};
  // A camera session's map (its visual landmarks) is stored as a LiDAR session's is.
  ASSERT_TRUE(manager_->save_session_maps().ok());
  auto survey_map = manager_->stored_map(admin, survey);
  ASSERT_TRUE(survey_map.ok()) << survey_map.error().message;
  msgs::FusionMap known = std::move(survey_map).value();
  ASSERT_TRUE(known.visual_landmarks.has_value());
  const SE3 T_known_survey(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), -2.0), Eigen::Vector3d(-20.0, 45.0, 1.0));
  for (Eigen::Vector3f& position : known.visual_landmarks->positions) position = (T_known_survey * position.cast<double>()).cast<float>();
  for (msgs::VisualKeyframe& keyframe : known.visual_landmarks->keyframes) {
    keyframe.T_world_camera = msgs::Pose::from_se3(T_known_survey * keyframe.T_world_camera.to_se3());
  }
  known.map_id = "hall-survey";
  known.version = 0;
  auto loaded = client().Post("/v1/maps?name=hall", bearer(kAdminToken), maps::serialize_fusion_map(known).value(), "application/octet-stream");
  ASSERT_TRUE(loaded && loaded->status == 201) << (loaded ? loaded->body : "");

  const Timestamp start = scenario.start_time + Duration::from_seconds(3.0);
  const std::string robot = manager_->create_session(kStreamer, {"robot", config_yaml, calibration_yaml}).value().id;
  const auto relocalize = [&](const std::string& body) {
    return client().Post("/v1/sessions/" + robot + "/relocalize", bearer(kRobotToken), body, "application/json");
  };
  EXPECT_EQ(relocalize(R"({"map_id": "hall-survey"})")->status, 409);  // no image yet
  for (const testing::TimedMessage& message : messages) {
    if (msgs::timestamp_of(message.message) >= start) {
      ASSERT_TRUE(manager_->push(kStreamer, robot, message.sensor, message.message).ok());
    }
  }
  EXPECT_EQ(error_of(relocalize(R"({"map_id": "hall-survey", "frames": 0})"))["field"], "frames");
  EXPECT_EQ(error_of(relocalize(R"({"map_id": "hall-survey", "frames": 2, "min_agreeing_frames": 3})"))["field"], "min_agreeing_frames");
  auto disagreeing = relocalize(R"({"map_id": "hall-survey", "agreement_m": 0})");
  ASSERT_TRUE(disagreeing);
  EXPECT_EQ(disagreeing->status, 422) << disagreeing->body;
  EXPECT_EQ(manager_->session_info(kStreamer, robot).value().mapping.relocalizations, 0U);

  auto relocalized = relocalize(R"({"map_id": "hall-survey"})");  // the session maps no LiDAR: its cameras
  ASSERT_TRUE(relocalized);
  ASSERT_EQ(relocalized->status, 200) << relocalized->body;
  const json outcome = json::parse(relocalized->body);
  EXPECT_EQ(outcome["sensor"], "camera");
  EXPECT_EQ(outcome["version"], 1);
  EXPECT_GE(outcome["agreeing_frames"].get<int>(), 2);
  ASSERT_EQ(outcome["placements"].size(), 3U);
  EXPECT_EQ(outcome["placements"][0]["placed"], true);
  EXPECT_EQ(manager_->session_info(kStreamer, robot).value().mapping.relocalizations, 1U);
  // Its pose is in the known map's frame now: where the survey's world (its body at the first
  // image), moved to the known place, has the true body.
  const msgs::PoseEstimate pose = manager_->current_pose(kStreamer, robot).value();
  const sim::SplineTrajectory& truth = simulation->trajectory();
  const SE3 expected = T_known_survey * truth.sample(scenario.start_time).T_world_body.inverse() *
                       truth.sample(pose.timestamp).T_world_body;
  std::printf("camera relocalization through REST: %d of 3 images agree, pose %.3f m from the truth in the map's frame\n",
              outcome["agreeing_frames"].get<int>(), (pose.T_world_body.position - expected.translation()).norm());
  EXPECT_LT((pose.T_world_body.position - expected.translation()).norm(), 0.25) << relocalized->body;
}

}  // namespace
}  // namespace hanzo::fusion::service
