#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/core/base64.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"

#include "hanzo/fusion/service/rest_server.hpp"
#include "service_fixtures.hpp"
#include "support/calibration_motion.hpp"
#include "support/checkerboard_views.hpp"

// Last: httplib pulls in <resolv.h>, whose `_res` macro breaks Eigen headers included after it.
#include <httplib.h>

namespace hanzo::fusion::service {
namespace {

using ::testing::HasSubstr;
using nlohmann::json;

constexpr const char* kRobotToken = "acme-robot-secret-0001";
constexpr const char* kViewerToken = "acme-viewer-secret-0002";
constexpr const char* kAdminToken = "acme-admin-secret-00003";
constexpr const char* kGlobexToken = "globex-robot-secret-0004";
constexpr const char* kGlobexAdminToken = "globex-admin-secret-0005";
constexpr const char* kMapperToken = "acme-mapper-secret-00006";
// Sensor data arrives over gRPC; these tests push through the SessionManager as that front end does.
const Principal kStreamer{"robot", "acme", static_cast<uint32_t>(Permission::kSessionWrite) | static_cast<uint32_t>(Permission::kSessionRead)};

class RestServerTest : public ::testing::Test {
 protected:
  void SetUp() override { start({}); }

  void start(RestServerConfig config) {
    rest_.reset();
    manager_.reset();
    dir_ = testing::scratch_dir();
    auto storage = open_storage("sqlite://" + (dir_ / "fusion.db").string());
    ASSERT_TRUE(storage.ok());
    metrics_ = std::make_shared<MetricsRegistry>();
    SessionManagerConfig manager_config;
    manager_config.map_directory = (dir_ / "maps").string();
    auto manager = SessionManager::create(manager_config, std::move(storage).value(), metrics_);
    ASSERT_TRUE(manager.ok());
    manager_ = std::move(manager).value();
    auto tokens = TokenStore::parse(testing::kTokensYaml, "tokens.yaml");
    ASSERT_TRUE(tokens.ok());
    config.bind_address = "127.0.0.1";
    config.port = 0;
    if (config.max_body_bytes == RestServerConfig{}.max_body_bytes) config.max_body_bytes = 256 * 1024;
    auto rest = RestServer::create(config, *manager_, std::make_shared<TokenStore>(std::move(tokens).value()), metrics_);
    ASSERT_TRUE(rest.ok()) << rest.error().message;
    rest_ = std::move(rest).value();
    ASSERT_TRUE(rest_->start().ok());
  }

  httplib::Client client() const {
    httplib::Client http("127.0.0.1", rest_->port());
    http.set_read_timeout(30, 0);
    return http;
  }
  static httplib::Headers bearer(const std::string& token) { return {{"Authorization", "Bearer " + token}}; }

  // POST /v1/sessions with the sample configuration; returns the session id.
  std::string create_session(const std::string& token = kRobotToken) {
    const json body = {{"name", "sample"}, {"config", testing::read_text("examples/data/fusion.yaml")}};
    auto response = client().Post("/v1/sessions", bearer(token), body.dump(), "application/json");
    EXPECT_TRUE(response);
    if (!response) return {};
    EXPECT_EQ(response->status, 201) << response->body;
    return json::parse(response->body).value("id", "");
  }

  static json error_of(const httplib::Result& response) {
    EXPECT_TRUE(response);
    if (!response) return {};
    const json body = json::parse(response->body);
    EXPECT_TRUE(body.contains("error")) << response->body;
    EXPECT_TRUE(body["error"].contains("code") && body["error"].contains("message") && body["error"].contains("field"));
    return body["error"];
  }

  std::filesystem::path dir_;
  std::shared_ptr<MetricsRegistry> metrics_;
  std::unique_ptr<SessionManager> manager_;
  std::unique_ptr<RestServer> rest_;
};

TEST_F(RestServerTest, SessionLifecycle) {
  const std::string id = create_session();
  ASSERT_FALSE(id.empty());
  auto http = client();
  auto got = http.Get(("/v1/sessions/" + id).c_str(), bearer(kViewerToken));
  ASSERT_TRUE(got);
  ASSERT_EQ(got->status, 200);
  const json session = json::parse(got->body);
  EXPECT_EQ(session["name"], "sample");
  EXPECT_EQ(session["organization"], "acme");
  EXPECT_EQ(session["status"], "active");
  EXPECT_EQ(session["sensors"].size(), 3u);
  EXPECT_TRUE(session["latest_pose"].is_null());

  auto listed = http.Get("/v1/sessions", bearer(kViewerToken));
  ASSERT_EQ(listed->status, 200);
  EXPECT_EQ(json::parse(listed->body)["sessions"].size(), 1u);
  EXPECT_EQ(json::parse(http.Get("/v1/sessions", bearer(kGlobexToken))->body)["sessions"].size(), 0u);

  // Register a sensor (JSON objects as configuration and calibration).
  const json sensor = {{"name", "radar"}, {"config", {{"rate", 10}}}, {"calibration", {{"translation", {1.0, 0.0, 0.2}}}}};
  auto registered = http.Post(("/v1/sessions/" + id + "/sensors").c_str(), bearer(kRobotToken), sensor.dump(), "application/json");
  ASSERT_EQ(registered->status, 201) << registered->body;
  EXPECT_EQ(json::parse(registered->body)["sensors"].size(), 4u);
  auto again = http.Post(("/v1/sessions/" + id + "/sensors").c_str(), bearer(kRobotToken), sensor.dump(), "application/json");
  EXPECT_EQ(again->status, 409);
  EXPECT_EQ(error_of(again)["code"], "conflict");

  // Stream the sample recording (through the manager, as the gRPC front end does), then read.
  for (const testing::TimedMessage& message : testing::sample_recording()) {
    ASSERT_TRUE(manager_->push(kStreamer, id, message.sensor, message.message).ok());
  }
  ASSERT_TRUE(manager_->flush_storage().ok());
  auto pose = http.Get(("/v1/sessions/" + id + "/pose").c_str(), bearer(kViewerToken));
  ASSERT_EQ(pose->status, 200);
  const json pose_json = json::parse(pose->body);
  const msgs::PoseEstimate latest = manager_->current_pose(kStreamer, id).value();
  EXPECT_EQ(pose_json["timestamp_ns"], latest.timestamp.nanoseconds());
  EXPECT_EQ(pose_json["position"][0].get<double>(), latest.T_world_body.position.x());
  EXPECT_EQ(pose_json["covariance"].size(), 36u);
  EXPECT_EQ(pose_json["state"], msgs::to_string(latest.status.state));
  // Each configured sensor's health rides on the pose.
  ASSERT_EQ(pose_json["sensor_health"].size(), manager_->session_info(kStreamer, id)->summary.sensors.size());
  EXPECT_EQ(pose_json["sensor_health"][0]["sensor"], "imu");
  EXPECT_EQ(pose_json["sensor_health"][0]["state"], "ok");

  // Trajectory, paged by 700.
  std::size_t total = 0;
  std::string after;
  int pages = 0;
  while (true) {
    const std::string path = "/v1/sessions/" + id + "/trajectory?limit=700" + (after.empty() ? "" : "&after=" + after);
    auto page = http.Get(path.c_str(), bearer(kViewerToken));
    ASSERT_EQ(page->status, 200) << page->body;
    const json body = json::parse(page->body);
    total += body["poses"].size();
    ++pages;
    if (body["next_after"].is_null()) break;
    after = std::to_string(body["next_after"].get<int64_t>());
  }
  const json info = json::parse(http.Get(("/v1/sessions/" + id).c_str(), bearer(kViewerToken))->body);
  EXPECT_EQ(total, info["stored_poses"].get<std::size_t>());
  for (const char* subscribers : {"pose_subscribers", "keyframe_subscribers", "map_subscribers"}) EXPECT_EQ(info[subscribers], 0) << subscribers;
  EXPECT_EQ(pages, static_cast<int>((total + 699) / 700));
  EXPECT_GT(total, 1800u);
  // A page's poses (written as text directly) carry the fields of GET /pose, numbers exact.
  const json first_page = json::parse(http.Get(("/v1/sessions/" + id + "/trajectory?limit=3").c_str(), bearer(kViewerToken))->body);
  const std::vector<msgs::PoseEstimate> stored = manager_->trajectory(kStreamer, id, Timestamp::from_nanoseconds(0), 3).value().poses;
  ASSERT_EQ(first_page["poses"].size(), 3u);
  for (std::size_t i = 0; i < 3; ++i) {
    const json& paged = first_page["poses"][i];
    for (const auto& [key, value] : pose_json.items()) EXPECT_TRUE(paged.contains(key)) << key;
    EXPECT_EQ(paged.size(), pose_json.size());
    EXPECT_EQ(paged["timestamp_ns"], stored[i].timestamp.nanoseconds());
    EXPECT_EQ(paged["frame_id"], pose_json["frame_id"]);  // "world", as GET /pose
    EXPECT_EQ(paged["child_frame_id"], pose_json["child_frame_id"]);
    EXPECT_EQ(paged["position"][2].get<double>(), stored[i].T_world_body.position.z());
    EXPECT_EQ(paged["orientation_wxyz"][0].get<double>(), stored[i].T_world_body.orientation.w());
    EXPECT_EQ(paged["velocity"][1].get<double>(), stored[i].velocity.y());
    ASSERT_TRUE(stored[i].pose_covariance.has_value());
    EXPECT_EQ(paged["covariance"][7].get<double>(), (*stored[i].pose_covariance)(1, 1));
    EXPECT_EQ(paged["state"], msgs::to_string(stored[i].status.state));
    EXPECT_EQ(paged["active_sensors"].size(), stored[i].status.active_sensors.size());
  }
  EXPECT_EQ(first_page["next_after"], stored[2].timestamp.nanoseconds());
  auto tum = http.Get(("/v1/sessions/" + id + "/trajectory?format=tum&limit=100").c_str(), bearer(kViewerToken));
  ASSERT_EQ(tum->status, 200);
  EXPECT_EQ(std::count(tum->body.begin(), tum->body.end(), '\n'), 100);
  EXPECT_TRUE(tum->has_header("X-Next-After"));
  // Large pages are compressed by the server at a fast level for clients that accept br or
  // gzip (httplib's own brotli runs at its slowest level); the content is the same.
  const std::string large = "/v1/sessions/" + id + "/trajectory?limit=1000";
  const auto fetch = [&](const std::string& accept_encoding) {
    httplib::Headers headers = bearer(kViewerToken);
    if (!accept_encoding.empty()) headers.emplace("Accept-Encoding", accept_encoding);
    return http.Get(large.c_str(), headers);
  };
  const auto plain = fetch("");
  ASSERT_EQ(plain->status, 200);
  EXPECT_FALSE(plain->has_header("Content-Encoding"));
  for (const std::string encoding : {"br", "gzip"}) {
    const auto compressed = fetch(encoding == "br" ? "gzip, deflate, br" : "gzip;q=1.0, br;q=0");
    ASSERT_EQ(compressed->status, 200);
    EXPECT_EQ(compressed->get_header_value("Content-Encoding"), encoding);
    EXPECT_EQ(compressed->body, plain->body) << encoding;
    EXPECT_LT(std::stoul(compressed->get_header_value("Content-Length")) * 2, plain->body.size()) << encoding;  // measured: 3.4x br, 3.0x gzip
  }

  auto deleted = http.Delete(("/v1/sessions/" + id).c_str(), bearer(kRobotToken));
  ASSERT_EQ(deleted->status, 200);
  EXPECT_EQ(json::parse(deleted->body)["status"], "ended");
  EXPECT_EQ(http.Delete(("/v1/sessions/" + id).c_str(), bearer(kRobotToken))->status, 409);
  EXPECT_EQ(http.Get(("/v1/sessions/" + id + "/trajectory?limit=5").c_str(), bearer(kViewerToken))->status, 200);
}

// The auth matrix of every operation of the OpenAPI document (docs/openapi.json, what the
// server serves), generated from it: each secured operation's x-required-permissions decides
// which of the fixture's tokens may call it. No token, an unknown token or another scheme: 401;
// a token of the organization lacking a required permission: 403; another organization's token
// (an admin's) on a session or map of this one: 403; a token with the permissions: neither.
// The files themselves, without escaping them into JSON: multipart form parts (curl -F
// config=@fusion.yaml -F calibration=@calibration.yaml) or the configuration as a YAML body.
TEST_F(RestServerTest, CreatesSessionsFromPostedYamlFiles) {
  auto http = client();
  const std::string configuration = testing::read_text("examples/data/fusion.yaml");  // imu, gnss, wheels
  const std::string calibration =
      "calibration:\n  imu_to_body: identity\n  gnss_to_body:\n    translation: [0.0, 0.0, 1.2]\n  wheels_to_body: identity\n";
  const httplib::MultipartFormDataItems form = {{"config", configuration, "fusion.yaml", "application/yaml"},
                                                {"calibration", calibration, "calibration.yaml", "application/yaml"},
                                                {"name", "from files", "", ""}};
  auto created = http.Post("/v1/sessions", bearer(kRobotToken), form);
  ASSERT_TRUE(created);
  ASSERT_EQ(created->status, 201) << created->body;
  const json session = json::parse(created->body);
  EXPECT_EQ(session["name"], "from files");
  EXPECT_EQ(session["sensors"].size(), 3u);
  EXPECT_THAT(session["calibration"].get<std::string>(), HasSubstr("imu_to_body"));

  auto yaml_body = http.Post("/v1/sessions?name=yaml%20body", bearer(kRobotToken), configuration, "application/yaml");
  ASSERT_TRUE(yaml_body);
  ASSERT_EQ(yaml_body->status, 201) << yaml_body->body;
  EXPECT_EQ(json::parse(yaml_body->body)["name"], "yaml body");
  // The calibration after the configuration in one YAML body (with or without ---) is taken too;
  // an error in it names the body's own line.
  auto both = http.Post("/v1/sessions?name=both", bearer(kRobotToken), configuration + "---\n" + calibration, "application/yaml");
  ASSERT_TRUE(both);
  ASSERT_EQ(both->status, 201) << both->body;
  EXPECT_THAT(json::parse(both->body)["calibration"].get<std::string>(), HasSubstr("gnss_to_body"));
  const std::size_t calibration_line = static_cast<std::size_t>(std::count(configuration.begin(), configuration.end(), '\n')) + 4;  // gnss's translation
  std::string broken_calibration = calibration;
  broken_calibration.replace(broken_calibration.find("1.2"), 3, "x");
  auto bad_both = http.Post("/v1/sessions", bearer(kRobotToken), configuration + broken_calibration, "application/yaml");
  EXPECT_EQ(bad_both->status, 400);
  EXPECT_THAT(error_of(bad_both)["message"].get<std::string>(), HasSubstr("calibration:" + std::to_string(calibration_line) + ":"));

  // Bad forms name what is wrong; nothing is created.
  const httplib::MultipartFormDataItems no_config = {{"calibration", calibration, "calibration.yaml", ""}};
  auto missing = http.Post("/v1/sessions", bearer(kRobotToken), no_config);
  EXPECT_EQ(missing->status, 400);
  EXPECT_EQ(error_of(missing)["field"], "config");
  const httplib::MultipartFormDataItems extra = {{"config", configuration, "", ""}, {"calibraton", calibration, "", ""}};
  auto unknown = http.Post("/v1/sessions", bearer(kRobotToken), extra);
  EXPECT_EQ(unknown->status, 400);
  EXPECT_THAT(error_of(unknown)["message"].get<std::string>(), HasSubstr("calibraton"));
  auto broken = http.Post("/v1/sessions", bearer(kRobotToken), "fusion: [unclosed", "application/yaml");
  EXPECT_EQ(broken->status, 400) << broken->body;
  EXPECT_EQ(json::parse(http.Get("/v1/sessions", bearer(kViewerToken))->body)["sessions"].size(), 3u);
}

TEST_F(RestServerTest, AuthMatrixOfEveryOperationInTheOpenApiDocument) {
  const std::string session_id = create_session();
  msgs::FusionMap map;
  map.map_id = "auth-matrix";
  map.points = msgs::PointLayer{};
  map.points->points = {Eigen::Vector3f(1.0F, 2.0F, 0.5F), Eigen::Vector3f(2.0F, 1.0F, 0.5F)};
  const std::string map_file = maps::serialize_fusion_map(map).value();
  auto loaded = client().Post("/v1/maps?name=auth", bearer(kMapperToken), map_file, "application/octet-stream");
  ASSERT_TRUE(loaded);
  ASSERT_EQ(loaded->status, 201) << loaded->body;
  const std::string map_id = json::parse(loaded->body).at("map_id");

  // The acme tokens' permissions (service_fixtures.hpp); fusion:admin grants every permission.
  const std::vector<std::pair<const char*, std::set<std::string>>> acme_tokens = {
      {kRobotToken, {"fusion:session:write", "fusion:session:read", "fusion:map:read"}},
      {kViewerToken, {"fusion:session:read"}},
      {kMapperToken, {"fusion:map:read", "fusion:map:write"}},
      {kAdminToken, {"fusion:admin"}}};
  const auto holds = [](const std::set<std::string>& permissions, const std::string& needed) {
    return permissions.count(needed) != 0 || permissions.count("fusion:admin") != 0;
  };
  struct Operation {
    std::string method, path_template, path, body, content_type;
    std::vector<std::string> permissions;
  };
  std::vector<Operation> operations;
  const json document = json::parse(testing::read_text("docs/openapi.json"));
  for (const auto& [path_template, item] : document.at("paths").items()) {
    for (const auto& [method, operation] : item.items()) {
      if (method == "parameters") continue;
      if (operation.contains("security") && operation["security"].empty()) continue;  // health, the document
      ASSERT_TRUE(operation.contains("x-required-permissions")) << method << " " << path_template;
      Operation entry{method, path_template, path_template, "", "application/json", operation["x-required-permissions"]};
      const std::string id = path_template.rfind("/v1/maps/", 0) == 0 ? map_id : session_id;
      if (const auto at = entry.path.find("{id}"); at != std::string::npos) entry.path.replace(at, 4, id);
      if (path_template == "/v1/sessions") entry.body = json({{"config", testing::read_text("examples/data/fusion.yaml")}}).dump();
      if (path_template == "/v1/sessions/{id}/sensors") entry.body = R"({"name": "wheels2", "config": {"rate": 50}})";
      if (path_template == "/v1/sessions/{id}/loop-closure") entry.body = "{}";
      if (path_template == "/v1/sessions/{id}/relocalize") entry.body = json({{"map_id", map_id}}).dump();
      if (path_template == "/v1/calibrate") entry.body = "{}";
      if (path_template == "/v1/maps") {
        entry.path += "?name=again";
        entry.body = map_file;
        entry.content_type = "application/octet-stream";
      }
      operations.push_back(std::move(entry));
    }
  }
  EXPECT_GE(operations.size(), 14U);
  // Deleting last (the session, then the map): everything else still finds them.
  std::stable_partition(operations.begin(), operations.end(), [](const Operation& op) { return op.method != "delete"; });

  auto http = client();
  auto call = [&](const Operation& op, const httplib::Headers& headers) {
    if (op.method == "get") return http.Get(op.path.c_str(), headers);
    if (op.method == "delete") return http.Delete(op.path.c_str(), headers);
    return http.Post(op.path.c_str(), headers, op.body, op.content_type.c_str());
  };
  for (const Operation& op : operations) {
    SCOPED_TRACE(op.method + " " + op.path_template);
    auto missing = call(op, {});
    ASSERT_TRUE(missing);
    EXPECT_EQ(missing->status, 401);
    EXPECT_EQ(error_of(missing)["code"], "unauthenticated");
    EXPECT_EQ(call(op, bearer("not-a-token-of-this-server"))->status, 401);
    EXPECT_EQ(call(op, {{"Authorization", "Basic abc"}})->status, 401);
    const char* allowed = nullptr;
    for (const auto& [token, permissions] : acme_tokens) {
      const bool may = std::all_of(op.permissions.begin(), op.permissions.end(), [&](const std::string& p) { return holds(permissions, p); });
      if (may) {
        if (allowed == nullptr) allowed = token;  // the least privileged: the admin comes last
        continue;
      }
      auto forbidden = call(op, bearer(token));
      EXPECT_EQ(forbidden->status, 403) << token << ": " << forbidden->body;
      EXPECT_EQ(error_of(forbidden)["code"], "permission_denied");
    }
    if (op.path_template.find("{id}") != std::string::npos) {
      auto other = call(op, bearer(kGlobexAdminToken));
      EXPECT_EQ(other->status, 403) << other->body;
      EXPECT_THAT(error_of(other)["message"].get<std::string>(), HasSubstr("another organization"));
    }
    ASSERT_NE(allowed, nullptr);
    auto permitted = call(op, bearer(allowed));
    ASSERT_TRUE(permitted);
    EXPECT_NE(permitted->status, 401);
    EXPECT_NE(permitted->status, 403) << allowed << ": " << permitted->body;
  }
  // The session survived all of it (and only its DELETE ended it); the map went with its DELETE.
  const json info = json::parse(http.Get(("/v1/sessions/" + session_id).c_str(), bearer(kViewerToken))->body);
  EXPECT_EQ(info["status"], "ended");
  EXPECT_EQ(info["sensors"].size(), 4u);
  EXPECT_EQ(http.Get(("/v1/maps/" + map_id + "?format=json").c_str(), bearer(kRobotToken))->status, 404);
}

TEST_F(RestServerTest, BadRequestsGetTheDocumentedErrors) {
  const std::string id = create_session();
  auto http = client();
  auto post = [&](const std::string& path, const std::string& body) {
    return http.Post(path.c_str(), bearer(kRobotToken), body, "application/json");
  };
  auto malformed = post("/v1/sessions", "{\"config\": ");
  EXPECT_EQ(malformed->status, 400);
  EXPECT_EQ(error_of(malformed)["field"], "body");
  EXPECT_THAT(error_of(malformed)["message"].get<std::string>(), HasSubstr("malformed JSON"));
  // A number beyond any type (found by libFuzzer): 400, not an exception out of the parser.
  auto overflow = post("/v1/sessions", R"({"name": "lidar", "config": 3333333333333333333333E0000000000000000000000000000000000000000026308527823222})");
  EXPECT_EQ(overflow->status, 400);
  EXPECT_THAT(error_of(overflow)["message"].get<std::string>(), HasSubstr("malformed JSON"));
  EXPECT_EQ(error_of(post("/v1/sessions", "[1, 2]"))["message"], "expected a JSON object");
  EXPECT_EQ(error_of(post("/v1/sessions", ""))["field"], "body");
  auto wrong_type = post("/v1/sessions", R"({"config": 5})");
  EXPECT_EQ(wrong_type->status, 400);
  EXPECT_EQ(error_of(wrong_type)["field"], "config");
  EXPECT_EQ(error_of(post("/v1/sessions", R"({"name": 7, "config": "x"})"))["field"], "name");
  EXPECT_EQ(error_of(post("/v1/sessions", R"({"config": "fusion: {}", "colour": 1})"))["field"], "colour");
  EXPECT_EQ(error_of(post("/v1/sessions", R"({"name": "no config"})"))["field"], "config");
  auto invalid_config = post("/v1/sessions", R"({"config": {"sensors": {"imu": {"rate": "fast"}}}})");
  EXPECT_EQ(invalid_config->status, 400);
  EXPECT_THAT(error_of(invalid_config)["message"].get<std::string>(), HasSubstr("rate"));
  auto nan_calibration = post("/v1/sessions", json({{"config", {{"sensors", {{"imu", {{"rate", 100}}}}}}},
                                                    {"calibration", "calibration:\n  imu_to_body: {translation: [.nan, 0, 0]}\n"}}).dump());
  EXPECT_EQ(nan_calibration->status, 400);

  // Oversized body: refused with 413 in the same JSON shape.
  auto oversized = post("/v1/sessions", std::string(300 * 1024, ' ') + "{}");
  EXPECT_EQ(oversized->status, 413);
  EXPECT_EQ(error_of(oversized)["code"], "payload_too_large");

  auto unknown = http.Get("/v1/sessions/ffffffffffffffff", bearer(kViewerToken));
  EXPECT_EQ(unknown->status, 404);
  EXPECT_EQ(error_of(unknown)["field"], "session_id");
  auto no_route = http.Get("/v1/nothing-here", bearer(kViewerToken));
  EXPECT_EQ(no_route->status, 404);
  EXPECT_THAT(error_of(no_route)["message"].get<std::string>(), HasSubstr("no route"));
  EXPECT_EQ(http.Get(("/v1/sessions/" + id + "/pose").c_str(), bearer(kViewerToken))->status, 404);  // no data yet
  EXPECT_EQ(error_of(http.Get(("/v1/sessions/" + id + "/trajectory?limit=0").c_str(), bearer(kViewerToken)))["field"], "limit");
  EXPECT_EQ(error_of(http.Get(("/v1/sessions/" + id + "/trajectory?limit=x").c_str(), bearer(kViewerToken)))["field"], "limit");
  EXPECT_EQ(error_of(http.Get(("/v1/sessions/" + id + "/trajectory?after=1e9").c_str(), bearer(kViewerToken)))["field"], "after");
  EXPECT_EQ(error_of(http.Get(("/v1/sessions/" + id + "/trajectory?format=csv").c_str(), bearer(kViewerToken)))["field"], "format");
  EXPECT_EQ(error_of(post("/v1/sessions/" + id + "/sensors", R"({"config": {"rate": 5}})"))["field"], "name");

  // Still intact and serving.
  auto session = http.Get(("/v1/sessions/" + id).c_str(), bearer(kViewerToken));
  EXPECT_EQ(session->status, 200);
  EXPECT_EQ(json::parse(session->body)["sensors"].size(), 3u);
}

// POST /v1/calibrate: hand-eye calibration of a sensor's odometry against body poses and
// against the gyroscope (exact truth: test_support::CalibrationScenario), and its errors.
TEST_F(RestServerTest, CalibrateRecoversExtrinsicsAndTimeOffset) {
  RestServerConfig config;
  config.max_body_bytes = 8u << 20;
  start(config);
  auto http = client();
  auto post = [&](const json& body) { return http.Post("/v1/calibrate", bearer(kRobotToken), body.dump(), "application/json"); };
  const auto tum_rows = [](const std::vector<calib::StampedPose>& poses) {
    json rows = json::array();
    for (const calib::StampedPose& stamped : poses) {
      const Eigen::Vector3d& p = stamped.pose.translation();
      const Eigen::Quaterniond& q = stamped.pose.rotation().quaternion();
      rows.push_back({stamped.time.seconds(), p.x(), p.y(), p.z(), q.x(), q.y(), q.z(), q.w()});
    }
    return rows;
  };
  test_support::CalibrationScenario scenario;
  const json sensor_poses = tum_rows(scenario.sensor_poses());
  const json body_poses = tum_rows(scenario.body_poses(50.0));
  const auto rotation_error_deg = [&](const json& result) {
    const std::vector<double> q = result.at("rotation_wxyz");
    const SO3 estimate(Eigen::Quaterniond(q[0], q[1], q[2], q[3]).normalized());
    return (scenario.T_body_sensor.rotation().inverse() * estimate).angle() / test_support::kDegToRad;
  };

  auto with_poses = post({{"sensor", "lidar"}, {"sensor_poses", sensor_poses}, {"body_poses", body_poses}});
  ASSERT_EQ(with_poses->status, 200) << with_poses->body;
  const json result = json::parse(with_poses->body);
  EXPECT_LT(rotation_error_deg(result), 0.05);
  const std::vector<double> translation = result.at("translation");
  EXPECT_LT((Eigen::Vector3d(translation[0], translation[1], translation[2]) - scenario.T_body_sensor.translation()).norm(), 0.005);
  EXPECT_NEAR(result.at("time_offset_ns").get<double>() * 1e-9, scenario.time_offset, 0.001);
  EXPECT_TRUE(result.at("translation_estimated").get<bool>());
  EXPECT_TRUE(result.at("unobservable_translation_axis").is_null());
  // The YAML entry loads as a calibration file.
  const Result<calib::Calibration> entry = calib::parse_calibration(result.at("calibration_yaml").get<std::string>(), "response");
  ASSERT_TRUE(entry.ok()) << entry.error().message;
  ASSERT_NE(entry->find("lidar"), nullptr);
  EXPECT_EQ(entry->find("lidar")->time_offset.nanoseconds(), result.at("time_offset_ns").get<int64_t>());

  json gyro = json::array();
  for (const calib::GyroSample& sample : scenario.gyro()) {
    gyro.push_back({sample.time.seconds(), sample.angular_velocity.x(), sample.angular_velocity.y(), sample.angular_velocity.z()});
  }
  auto with_gyro = post({{"sensor", "camera_left"}, {"sensor_poses", sensor_poses}, {"gyro", gyro}, {"max_time_offset", 0.1}});
  ASSERT_EQ(with_gyro->status, 200) << with_gyro->body;
  const json gyro_result = json::parse(with_gyro->body);
  EXPECT_LT(rotation_error_deg(gyro_result), 0.1);
  EXPECT_NEAR(gyro_result.at("time_offset_ns").get<double>() * 1e-9, scenario.time_offset, 0.001);
  EXPECT_FALSE(gyro_result.at("translation_estimated").get<bool>());
  EXPECT_NEAR(gyro_result.at("gyro_bias")[1].get<double>(), scenario.gyro_bias.y(), 0.001);

  // Bad requests name their field (400); motion that cannot calibrate is refused (422).
  const auto error_field = [&](const json& body) {
    auto response = post(body);
    EXPECT_EQ(response->status, 400) << response->body;
    return error_of(response)["field"].get<std::string>();
  };
  EXPECT_EQ(error_field({{"sensor", "lidar"}, {"sensor_poses", sensor_poses}}), "body_poses");
  EXPECT_EQ(error_field({{"sensor_poses", sensor_poses}, {"body_poses", body_poses}}), "sensor");
  json short_row = sensor_poses;
  short_row[3] = {1.0, 2.0};
  EXPECT_EQ(error_field({{"sensor", "lidar"}, {"sensor_poses", short_row}, {"body_poses", body_poses}}), "sensor_poses[3]");
  json repeated = sensor_poses;
  repeated[12][0] = repeated[11][0];
  EXPECT_EQ(error_field({{"sensor", "lidar"}, {"sensor_poses", repeated}, {"body_poses", body_poses}}), "sensor_poses[12]");
  json not_unit = body_poses;
  not_unit[5][7] = 2.0;
  EXPECT_EQ(error_field({{"sensor", "lidar"}, {"sensor_poses", sensor_poses}, {"body_poses", not_unit}}), "body_poses[5]");
  EXPECT_EQ(error_field({{"sensor", "lidar"}, {"sensor_poses", sensor_poses}, {"body_poses", body_poses}, {"pair_interval", -1}}),
            "pair_interval");
  EXPECT_EQ(error_field({{"sensor", "lidar"}, {"sensor_poses", sensor_poses}, {"body_poses", body_poses}, {"colour", 1}}), "colour");

  test_support::CalibrationScenario turning_only;
  turning_only.body.roll_pitch = 0.0;
  auto one_axis = post({{"sensor", "lidar"}, {"sensor_poses", tum_rows(turning_only.sensor_poses())},
                        {"body_poses", tum_rows(turning_only.body_poses(50.0))}});
  EXPECT_EQ(one_axis->status, 422) << one_axis->body;
  EXPECT_THAT(error_of(one_axis)["message"].get<std::string>(), HasSubstr("one axis"));
  EXPECT_EQ(http.Post("/v1/calibrate", bearer(kViewerToken), "{}", "application/json")->status, 403);  // session:read only
}

// POST /v1/calibrate with "procedure": "camera_intrinsics": PNG files (base64) of a checkerboard
// rendered through a known lens give back its intrinsics; bad images name their field.
TEST_F(RestServerTest, CalibrateCameraIntrinsicsFromUploadedImages) {
  RestServerConfig config;
  config.max_body_bytes = 12u << 20;  // 12 noisy 752 x 480 PNG files: about 5 MB as base64
  start(config);
  auto http = client();
  const sim::CameraSimulatorConfig truth = test_support::lens(
      {458.654, 457.296, 367.215, 248.375, 752, 480}, {msgs::DistortionType::kRadtan, {-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05}});
  const std::vector<msgs::ImageMessage> views = test_support::render_views(truth, 12, {0.2, 0.12});
  json images = json::array();
  for (const msgs::ImageMessage& view : views) {
    ASSERT_EQ(view.encoding, msgs::ImageEncoding::kMono8);
    const cv::Mat image(static_cast<int>(view.height), static_cast<int>(view.width), CV_8UC1, const_cast<uint8_t*>(view.data.data()));
    std::vector<uint8_t> png;
    ASSERT_TRUE(cv::imencode(".png", image, png));
    images.push_back({{"data", base64_encode(png)}, {"timestamp_ns", view.timestamp.nanoseconds()}});
  }
  const json request = {{"procedure", "camera_intrinsics"},
                        {"sensor", "camera_front"},
                        {"board", {{"inner_corners_x", test_support::kCornersX}, {"inner_corners_y", test_support::kCornersY},
                                   {"square_size", test_support::kSquare}}},
                        {"images", images}};
  auto post = [&](const json& body) { return http.Post("/v1/calibrate", bearer(kRobotToken), body.dump(), "application/json"); };
  auto calibrated = post(request);
  ASSERT_EQ(calibrated->status, 200) << calibrated->body.substr(0, 500);
  const json result = json::parse(calibrated->body);
  std::printf("camera_intrinsics over REST: %zu bytes of request, fx %.2f fy %.2f cx %.2f cy %.2f, %d views used, RMS %.3f px\n",
              request.dump().size(), result["intrinsics"]["fx"].get<double>(), result["intrinsics"]["fy"].get<double>(),
              result["intrinsics"]["cx"].get<double>(), result["intrinsics"]["cy"].get<double>(), result["views_used"].get<int>(),
              result["rms_px"].get<double>());
  EXPECT_EQ(result.at("sensor"), "camera_front");
  EXPECT_EQ(result.at("images"), 12);
  EXPECT_GE(result.at("views_used").get<int>(), 8);
  EXPECT_LT(result.at("rms_px").get<double>(), 0.2);
  const json& k = result.at("intrinsics");
  EXPECT_NEAR(k.at("fx").get<double>(), truth.intrinsics.fx, 2.5);
  EXPECT_NEAR(k.at("fy").get<double>(), truth.intrinsics.fy, 2.5);
  EXPECT_NEAR(k.at("cx").get<double>(), truth.intrinsics.cx, 2.5);
  EXPECT_NEAR(k.at("cy").get<double>(), truth.intrinsics.cy, 2.5);
  EXPECT_EQ(k.at("width"), 752);
  EXPECT_EQ(result.at("distortion_model"), "radtan");
  EXPECT_NEAR(result.at("distortion_coeffs")[0].get<double>(), -0.2834, 0.03);
  EXPECT_EQ(result.at("views")[0].at("timestamp_ns"), views[0].timestamp.nanoseconds());

  // Bad requests name their field (400); too few views with the whole board cannot calibrate (422).
  const auto error_field = [&](const json& body) {
    auto response = post(body);
    EXPECT_EQ(response->status, 400) << response->body;
    return error_of(response)["field"].get<std::string>();
  };
  json bad = request;
  bad["images"][1]["data"] = "not base64!";
  EXPECT_EQ(error_field(bad), "images[1].data");
  bad = request;
  bad["images"][2]["data"] = base64_encode(std::vector<uint8_t>{'h', 'e', 'l', 'l', 'o'});
  EXPECT_EQ(error_field(bad), "images[2].data");
  bad = request;
  std::vector<uint8_t> deep_png;
  ASSERT_TRUE(cv::imencode(".png", cv::Mat(48, 64, CV_16UC1, cv::Scalar(1000)), deep_png));
  bad["images"][0]["data"] = base64_encode(deep_png);
  EXPECT_EQ(error_field(bad), "images[0].data");
  bad = request;
  bad["images"][0]["colour"] = 1;
  EXPECT_EQ(error_field(bad), "images[0].colour");
  bad = request;
  bad["board"].erase("square_size");
  EXPECT_EQ(error_field(bad), "board.square_size");
  bad = request;
  bad["model"] = "pinhole";
  EXPECT_EQ(error_field(bad), "model");
  bad = request;
  bad["procedure"] = "stereo";
  EXPECT_EQ(error_field(bad), "procedure");
  bad = request;
  bad["images"] = json::array();
  EXPECT_EQ(error_field(bad), "images");
  bad = request;
  bad["images"] = json::array({images[0], images[1], images[2]});
  auto too_few = post(bad);
  EXPECT_EQ(too_few->status, 422) << too_few->body;
  EXPECT_THAT(error_of(too_few)["message"].get<std::string>(), HasSubstr("6 views are needed"));
}

TEST_F(RestServerTest, HealthOpenApiAndMetrics) {
  auto http = client();
  auto health = http.Get("/v1/health");
  ASSERT_EQ(health->status, 200);
  EXPECT_EQ(json::parse(health->body)["storage"], "sqlite");
  EXPECT_EQ(json::parse(health->body)["auth"], true);

  auto openapi = http.Get("/v1/openapi.json");
  ASSERT_EQ(openapi->status, 200);
  EXPECT_EQ(openapi->body, testing::read_text(std::string(HANZO_SOURCE_DIR) + "/docs/openapi.json"));
  const std::string id = create_session();
  auto metrics = http.Get("/v1/metrics", bearer(kAdminToken));
  ASSERT_EQ(metrics->status, 200);
  EXPECT_THAT(metrics->get_header_value("Content-Type"), HasSubstr("text/plain; version=0.0.4"));
  EXPECT_THAT(metrics->body, HasSubstr("hanzo_fusion_http_requests_total{method=\"GET\",route=\"/v1/health\",status=\"200\"} 1.0"));
  EXPECT_THAT(metrics->body, HasSubstr("hanzo_fusion_active_sessions 1.0"));
  EXPECT_THAT(metrics->body, HasSubstr("hanzo_fusion_messages_received_total{session=\"" + id + "\",sensor=\"imu\"} 0.0"));

  // Every documented operation is routed (answers something other than "no route").
  const json document = json::parse(openapi->body);
  auto http_admin = client();
  for (const auto& [path_template, operations] : document["paths"].items()) {
    std::string path = path_template;
    if (const auto brace = path.find("{id}"); brace != std::string::npos) path.replace(brace, 4, id);
    for (const auto& [method, operation] : operations.items()) {
      if (method == "parameters") continue;
      httplib::Result response = method == "get"    ? http_admin.Get(path.c_str(), bearer(kAdminToken))
                                 : method == "post" ? http_admin.Post(path.c_str(), bearer(kAdminToken), "{}", "application/json")
                                                    : http_admin.Delete(path.c_str(), bearer(kAdminToken));
      ASSERT_TRUE(response) << method << " " << path;
      EXPECT_THAT(response->body, ::testing::Not(HasSubstr("no route"))) << method << " " << path;
    }
  }

}

TEST_F(RestServerTest, ServesHttpsWithTheGivenCertificate) {
  const auto certificates = testing::scratch_dir("_tls");
  const std::string certificate = (certificates / "server.crt").string();
  const std::string key = (certificates / "server.key").string();
  const std::string command = "openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj /CN=127.0.0.1 -keyout " + key +
                              " -out " + certificate + " >/dev/null 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0);
  RestServerConfig config;
  config.tls_certificate = certificate;
  config.tls_private_key = key;
  start(config);
  ASSERT_TRUE(rest_->https());
  httplib::SSLClient https("127.0.0.1", rest_->port());
  https.set_ca_cert_path(certificate.c_str());
  https.enable_server_certificate_verification(true);
  auto health = https.Get("/v1/health");
  ASSERT_TRUE(health) << httplib::to_string(health.error());
  EXPECT_EQ(health->status, 200);
  EXPECT_FALSE(client().Get("/v1/health")) << "plain HTTP is not served on the HTTPS port";

  // Key and certificate that do not load are refused at creation.
  config.tls_private_key = certificate;
  auto storage = open_storage("sqlite://" + (certificates / "other.db").string());
  auto manager = SessionManager::create({}, std::move(storage).value(), nullptr);
  EXPECT_FALSE(RestServer::create(config, *manager.value(), nullptr, nullptr).ok());
  config.tls_private_key.clear();
  EXPECT_THAT(RestServer::create(config, *manager.value(), nullptr, nullptr).error().message, HasSubstr("both"));
}

}  // namespace
}  // namespace hanzo::fusion::service
