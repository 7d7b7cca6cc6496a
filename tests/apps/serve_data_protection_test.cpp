// Data protection end to end through `hanzo-fusion serve`: a camera session of one organization
// (an OIDC token) records its drive through the privacy filter, encrypted, into an S3 server
// (s3rver on 127.0.0.1), with its map version next to it; a token of the organization reads both
// back, a token of another organization reads neither, and a restarted server still serves them
// from the bucket.
#include <filesystem>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/crypto/file_encryption.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/privacy/privacy_filter.hpp"
#include "serve_process.hpp"
#include "support/local_s3_server.hpp"

namespace hanzo::fusion {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using testing::read_file;
using testing::Server;

int run_cli(const std::string& arguments) { return std::system(fmt::format("{} {} >/dev/null 2>&1", HANZO_FUSION_CLI, arguments).c_str()); }

std::vector<io::LogEntry> read_log(const std::string& path) {
  std::vector<io::LogEntry> entries;
  auto reader = io::SensorLogReader::open(path);
  EXPECT_TRUE(reader) << (reader ? "" : reader.error().message);
  io::LogEntry entry;
  while (reader) {
    auto more = (*reader)->next(entry);
    if (!more || !*more) break;
    entries.push_back(entry);
  }
  return entries;
}

// The simulated drive with its first camera frame replaced by a real photo of two faces, as the
// camera would deliver it (the camera's size, rgb8).
msgs::ImageMessage write_drive_with_faces(const fs::path& simulated, const fs::path& drive) {
  msgs::ImageMessage photo;
  auto writer = io::SensorLogWriter::open(drive.string());
  EXPECT_TRUE(writer);
  for (io::LogEntry& entry : read_log(simulated.string())) {
    if (!std::holds_alternative<msgs::SensorMessage>(entry.message)) continue;
    auto& message = std::get<msgs::SensorMessage>(entry.message);
    if (auto* image = std::get_if<msgs::ImageMessage>(&message); image != nullptr && photo.data.empty()) {
      const cv::Mat original = cv::imread(std::string(HANZO_DATA_DIR) + "/privacy_faces/obama_and_biden.jpg", cv::IMREAD_COLOR);
      EXPECT_FALSE(original.empty());
      cv::Mat sized, rgb;
      cv::resize(original, sized, cv::Size(static_cast<int>(image->width), static_cast<int>(image->height)));
      cv::cvtColor(sized, rgb, cv::COLOR_BGR2RGB);
      image->encoding = msgs::ImageEncoding::kRgb8;
      image->data.assign(rgb.data, rgb.data + rgb.total() * rgb.elemSize());
      photo = *image;
    }
    EXPECT_TRUE((*writer)->write(entry.topic, message, entry.topic.substr(entry.topic.rfind('/') + 1)));
  }
  EXPECT_TRUE((*writer)->close());
  return photo;
}

std::size_t faces_in(const msgs::ImageMessage& image) {
  auto filter = privacy::PrivacyFilter::create({});
  EXPECT_TRUE(filter) << (filter ? "" : filter.error().message);
  cv::Mat rgb(static_cast<int>(image.height), static_cast<int>(image.width), CV_8UC3, const_cast<uint8_t*>(image.data.data())), bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  auto found = (*filter)->detect(bgr);
  EXPECT_TRUE(found);
  std::size_t faces = 0;
  for (const privacy::RedactedRegion& region : *found) faces += region.kind == "face";
  return faces;
}

TEST(ServeDataProtection, ACameraSessionRecordsBlurredAndEncryptedIntoS3AndOnlyItsOrganizationReadsIt) {
  const fs::path dir = fs::temp_directory_path() / fmt::format("hanzo_cli_data_protection_{}", ::getpid());
  fs::remove_all(dir);
  fs::create_directories(dir);
  testing::LocalS3Server s3(dir / "s3", "fleet");
  ASSERT_EQ(s3.error(), "");
  testing::LocalS3Server::use_credentials();
  ASSERT_EQ(std::system(fmt::format("/usr/bin/python3 {}/tests/apps/jwt_fixture.py {}", HANZO_SOURCE_DIR, (dir / "jwt").string()).c_str()), 0);
  ASSERT_EQ(run_cli(fmt::format("crypto keygen {}", (dir / "key").string())), 0);
  ASSERT_EQ(run_cli(fmt::format("sim {}/examples/scenarios/warehouse_robot.yaml --out {} --duration 4 --no-foxglove", HANZO_SOURCE_DIR,
                                (dir / "sim").string())),
            0);
  const msgs::ImageMessage photo = write_drive_with_faces(dir / "sim" / "sensors.mcap", dir / "drive.mcap");
  ASSERT_GE(faces_in(photo), 2u);

  const std::string arguments =
      fmt::format("--data-dir {} --object-store {} --encryption-key {} --record-sessions --jwks {} --jwt-issuer https://login.example.com/ "
                  "--jwt-audience hanzo-fusion",
                  (dir / "data").string(), s3.url("site-a"), (dir / "key").string(), (dir / "jwt" / "jwks.json").string());
  auto server = std::make_unique<Server>(dir, arguments);
  ASSERT_GT(server->port(), 0) << server->err();
  const auto bearer = [&](const std::string& token) { return fmt::format("-H 'Authorization: Bearer {}'", read_file(dir / "jwt" / (token + ".jwt"))); };

  // acme's robot drives: a session created and streamed with acme's token.
  const auto created = server->request("/v1/sessions", fmt::format("{} -F config=@{} -F calibration=@{}", bearer("acme_operator"),
                                                                   (dir / "sim" / "fusion.yaml").string(), (dir / "sim" / "calibration.yaml").string()));
  ASSERT_EQ(created.first, 201) << created.second;
  const std::string id = nlohmann::json::parse(created.second)["id"];
  ASSERT_EQ(run_cli(fmt::format("stream {} --session {} --server 127.0.0.1:{} --rest http://127.0.0.1:{} --config {} --token {} --rate max",
                                (dir / "drive.mcap").string(), id, server->grpc_port(), server->port(), (dir / "sim" / "fusion.yaml").string(),
                                read_file(dir / "jwt" / "acme_operator.jwt"))),
            0);
  const auto ended = server->request("/v1/sessions/" + id, "-X DELETE " + bearer("acme_operator"));
  ASSERT_EQ(ended.first, 200) << ended.second;
  const nlohmann::json recording = nlohmann::json::parse(ended.second)["recording"];
  EXPECT_EQ(recording["status"], "finished") << recording.dump();
  EXPECT_TRUE(recording["encrypted"].get<bool>());
  EXPECT_GE(recording["privacy_audit"]["faces"].get<int>(), 2);
  EXPECT_EQ(recording["location"], fmt::format("s3://fleet/site-a/recordings/{}.mcap.enc", id));

  // In the bucket: the encrypted recording and the map version; nothing left on the server's disk.
  const fs::path bucket = s3.data_folder() / "site-a";
  const fs::path stored_recording = bucket / "recordings" / (id + ".mcap.enc._S3rver_object");
  ASSERT_TRUE(fs::exists(stored_recording));
  EXPECT_TRUE(crypto::is_encrypted_file(stored_recording.string()));
  const fs::path stored_map = bucket / "maps" / id / "00000000000000000001.fmap._S3rver_object";
  ASSERT_TRUE(fs::exists(stored_map));
  EXPECT_TRUE(crypto::is_encrypted_file(stored_map.string()));
  EXPECT_FALSE(fs::exists(dir / "data" / "recordings" / (id + ".mcap.enc")));
  EXPECT_FALSE(fs::exists(dir / "data" / "maps"));

  const auto check_reads = [&](Server& running) {
    // acme reads the recording (as stored: encrypted) and the map (decrypted by the server).
    const auto downloaded = running.request("/v1/sessions/" + id + "/recording", bearer("acme_operator") + " -o " + (dir / "download.enc").string());
    ASSERT_EQ(downloaded.first, 200) << read_file(dir / "download.enc");
    ASSERT_EQ(*hanzo::fusion::read_file((dir / "download.enc").string()), *hanzo::fusion::read_file(stored_recording.string()));
    auto key = crypto::EncryptionKey::load((dir / "key").string());
    ASSERT_TRUE(key);
    ASSERT_TRUE(crypto::decrypt_file((dir / "download.enc").string(), (dir / "download.mcap").string(), {*key}));
    const std::vector<io::LogEntry> recorded = read_log((dir / "download.mcap").string());
    const auto image = std::find_if(recorded.begin(), recorded.end(), [&](const io::LogEntry& entry) {
      const auto* sensor = std::get_if<msgs::SensorMessage>(&entry.message);
      const auto* message = sensor == nullptr ? nullptr : std::get_if<msgs::ImageMessage>(sensor);
      return message != nullptr && message->timestamp == photo.timestamp;
    });
    ASSERT_NE(image, recorded.end());
    EXPECT_EQ(faces_in(std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>(image->message))), 0u);  // blurred before it was written

    const auto map = running.request("/v1/maps/" + id + "?format=fmap", bearer("acme_operator") + " -o " + (dir / "map.fmap").string());
    ASSERT_EQ(map.first, 200);
    auto parsed = maps::read_fusion_map((dir / "map.fmap").string());
    ASSERT_TRUE(parsed) << parsed.error().message;
    EXPECT_EQ(parsed->map_id, id);
    EXPECT_GT(parsed->points->points.size(), 1000u);

    // globex's token: neither the recording nor the map.
    EXPECT_THAT(running.request("/v1/sessions/" + id + "/recording", bearer("globex_operator")).first, ::testing::AnyOf(403, 404));
    EXPECT_THAT(running.request("/v1/maps/" + id + "?format=fmap", bearer("globex_operator")).first, ::testing::AnyOf(403, 404));
    EXPECT_EQ(running.request("/v1/sessions/" + id + "/recording").first, 401);
  };
  check_reads(*server);
  server->stop(SIGTERM);
  Server restarted(dir, arguments);  // the same bucket, a fresh process
  ASSERT_GT(restarted.port(), 0) << restarted.err();
  check_reads(restarted);
  restarted.stop(SIGTERM);

  // A bucket that does not exist stops the start with S3's reason.
  Server refused(dir, fmt::format("--data-dir {} --insecure-no-auth --object-store '{}'", (dir / "other").string(),
                                  fmt::format("s3://no-such-bucket/x?endpoint={}", s3.endpoint())));
  EXPECT_EQ(refused.port(), 0);
  refused.wait();
  EXPECT_THAT(refused.err(), HasSubstr("--object-store: "));
  EXPECT_THAT(refused.err(), HasSubstr("NoSuchBucket"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace hanzo::fusion
