// `hanzo-fusion serve` as a process: refuses to start without tokens, says when auth is off,
// serves REST, stops cleanly on SIGTERM and keeps its sessions across restarts and kill -9.
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "serve_process.hpp"

namespace {

using ::testing::HasSubstr;
using nlohmann::json;
using hanzo::fusion::testing::read_file;
using hanzo::fusion::testing::Server;

constexpr const char* kTokens = R"(tokens:
  - name: robot
    organization: acme
    permissions: [fusion:session:write, fusion:session:read, fusion:admin]
    token: "acme-robot-secret-0001"
)";
constexpr const char* kAuthorization = "-H 'Authorization: Bearer acme-robot-secret-0001'";

TEST(ServeCli, RefusesToStartWithoutTokensAndSaysWhenAuthIsOff) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "hanzo_cli_serve_refuse";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  Server refused(dir, fmt::format("--data-dir {}", (dir / "data").string()));
  EXPECT_EQ(refused.port(), 0);
  const int exit_status = refused.wait();
  EXPECT_TRUE(WIFEXITED(exit_status) && WEXITSTATUS(exit_status) == 1);
  const std::string reason = refused.err();
  EXPECT_THAT(reason, HasSubstr("--insecure-no-auth"));
  EXPECT_EQ(std::count(reason.begin(), reason.end(), '\n'), 1);

  Server open(dir, fmt::format("--data-dir {} --insecure-no-auth", (dir / "data").string()));
  ASSERT_GT(open.port(), 0) << open.err();
  EXPECT_THAT(open.err(), HasSubstr("authentication is OFF"));
  EXPECT_EQ(open.request("/v1/sessions").first, 200);
  std::filesystem::remove_all(dir);
}

// Bearer JWTs of an OIDC provider (tokens signed by tests/apps/jwt_fixture.py with the openssl
// CLI): a valid token reads sessions, an expired or wrong-audience one gets 401 with the reason,
// one without fusion scopes 403.
TEST(ServeCli, AcceptsOidcJwtsAndRefusesBadOnesWithTheReason) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_serve_jwt_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  ASSERT_EQ(std::system(fmt::format("/usr/bin/python3 {}/tests/apps/jwt_fixture.py {}", HANZO_SOURCE_DIR, (dir / "jwt").string()).c_str()), 0);
  Server server(dir, fmt::format("--data-dir {} --jwks {} --jwt-issuer https://login.example.com/ --jwt-audience hanzo-fusion",
                                 (dir / "data").string(), (dir / "jwt" / "jwks.json").string()));
  ASSERT_GT(server.port(), 0) << server.err();
  const auto with = [&](const std::string& name) {
    return server.request("/v1/sessions", fmt::format("-H 'Authorization: Bearer {}'", read_file(dir / "jwt" / (name + ".jwt"))));
  };
  EXPECT_EQ(with("valid").first, 200) << with("valid").second;
  const auto expired = with("expired");
  EXPECT_EQ(expired.first, 401);
  EXPECT_THAT(expired.second, HasSubstr("token expired at"));
  const auto audience = with("wrong_audience");
  EXPECT_EQ(audience.first, 401);
  EXPECT_THAT(audience.second, HasSubstr("audience \\\"another-service\\\" is not 'hanzo-fusion'"));
  const auto no_scope = with("no_scope");
  EXPECT_EQ(no_scope.first, 403);
  EXPECT_THAT(no_scope.second, HasSubstr("lacks the permission fusion:session:read"));
  EXPECT_EQ(server.request("/v1/sessions").first, 401);
  server.stop(SIGTERM);
  // A JWKS that is not one stops the start with the reason.
  std::ofstream(dir / "bad.json") << "{\"keys\": 3}";
  Server refused(dir, fmt::format("--data-dir {} --jwks {} --jwt-issuer i --jwt-audience a", (dir / "data").string(), (dir / "bad.json").string()));
  EXPECT_EQ(refused.port(), 0);
  refused.wait();
  EXPECT_THAT(refused.err(), HasSubstr("bad.json: JWKS: expected a JSON object with a \"keys\" list"));
  std::filesystem::remove_all(dir);
}

TEST(ServeCli, SessionsSurviveSigtermAndKillNine) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / "hanzo_cli_serve_restart";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "tokens.yaml") << kTokens;
  const std::string arguments = fmt::format("--data-dir {} --tokens {}", (dir / "data").string(), (dir / "tokens.yaml").string());
  std::string id;
  std::ofstream(dir / "create.json") << json({{"name", "survivor"}, {"config", read_file("examples/data/fusion.yaml")}}).dump();
  {
    Server server(dir, arguments);
    ASSERT_GT(server.port(), 0) << server.err();
    EXPECT_EQ(server.request("/v1/health").first, 200);
    EXPECT_EQ(server.request("/v1/sessions").first, 401);
    const auto [status, body] =
        server.request("/v1/sessions", fmt::format("{} -X POST --data-binary @{}", kAuthorization, (dir / "create.json").string()));
    ASSERT_EQ(status, 201) << body;
    id = json::parse(body)["id"];
    const int exit_status = server.stop(SIGTERM);
    EXPECT_TRUE(WIFEXITED(exit_status) && WEXITSTATUS(exit_status) == 0) << server.err();
  }
  {
    Server server(dir, arguments);
    ASSERT_GT(server.port(), 0) << server.err();
    const auto [status, body] = server.request("/v1/sessions/" + id, kAuthorization);
    ASSERT_EQ(status, 200) << body;
    EXPECT_EQ(json::parse(body)["name"], "survivor");
    EXPECT_EQ(json::parse(body)["status"], "active");
    server.stop(SIGKILL);
  }
  Server server(dir, arguments);
  ASSERT_GT(server.port(), 0) << server.err();
  const auto [status, body] = server.request("/v1/sessions", kAuthorization);
  ASSERT_EQ(status, 200);
  EXPECT_EQ(json::parse(body)["sessions"].size(), 1u);
  std::filesystem::remove_all(dir);
}

// `drive --server`: a VLP-16 sent over loopback UDP at its recorded pace (`send`) goes, as
// `drive` decodes it, into a session the command creates on the server; the session takes every
// rotation. A server that does not answer fails the command, naming the address.
TEST(ServeCli, DriveSendsLiveSensorsIntoAServerSession) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / fmt::format("hanzo_cli_drive_server_{}", ::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "tokens.yaml") << kTokens;
  Server server(dir, fmt::format("--data-dir {} --tokens {}", (dir / "data").string(), (dir / "tokens.yaml").string()));
  ASSERT_GT(server.port(), 0) << server.err();
  const std::string veloview = std::string(HANZO_DATA_DIR) + "/drivers/velodyne_veloview/";
  const int port = 20000 + (::getpid() + 7919) % 20000;
  std::ofstream(dir / "fusion.yaml") << fmt::format(
      "fusion:\n  sensors:\n    lidar:\n      modality: lidar\n      topic: /lidar\n      rate: 20\n      driver:\n        type: velodyne\n"
      "        source: udp://127.0.0.1:{}\n        model: VLP-16\n        calibration: {}calib/VLP-16.xml\n",
      port, veloview);
  const std::string drive_command =
      fmt::format("{0} drive --config {1}/fusion.yaml --server 127.0.0.1:{2} --rest http://127.0.0.1:{3} --token acme-robot-secret-0001 "
                  "--name live --duration 5 --json > {1}/drive.json 2> {1}/drive.err",
                  HANZO_FUSION_CLI, dir.string(), server.grpc_port(), server.port());
  int drive_status = -1;
  std::thread driver([&] { drive_status = std::system(drive_command.c_str()); });
  std::this_thread::sleep_for(std::chrono::seconds(1));
  const int sent = std::system(fmt::format("{} send {}vlp-16-test-90deg-1-50-frames.pcap --port {} > /dev/null", HANZO_FUSION_CLI, veloview, port).c_str());
  driver.join();
  EXPECT_EQ(sent, 0);
  ASSERT_EQ(drive_status, 0) << read_file(dir / "drive.err");
  const json drive = json::parse(read_file(dir / "drive.json"));
  const json& lidar = drive["sensors"]["lidar"];
  EXPECT_GE(lidar["messages"].get<int>(), 50) << drive.dump();
  EXPECT_EQ(drive["server"]["messages_sent"], lidar["messages"]);
  EXPECT_EQ(drive["server"]["accepted"], lidar["messages"]);
  EXPECT_EQ(drive["server"]["send_errors"], 0);
  const auto [status, body] = server.request("/v1/sessions/" + drive["session_id"].get<std::string>(), kAuthorization);
  ASSERT_EQ(status, 200) << body;
  EXPECT_EQ(json::parse(body)["name"], "live");
  const int nobody = std::system(fmt::format("{0} drive --config {1}/fusion.yaml --server 127.0.0.1:1 --token x --duration 1 > /dev/null 2> {1}/nobody.err",
                                             HANZO_FUSION_CLI, dir.string()).c_str());
  EXPECT_NE(nobody, 0);
  EXPECT_THAT(read_file(dir / "nobody.err"), HasSubstr("127.0.0.1"));
  std::filesystem::remove_all(dir);
}

}  // namespace
