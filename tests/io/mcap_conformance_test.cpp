// Conformance with Foxglove's own MCAP implementation (@mcap/core + @mcap/support, run with
// node; installed by scripts/install-deps.sh into tests/conformance/node_modules):
//  - files written here are read there (indexed and streamed, every CRC checked, the same
//    messages back, protobuf payloads decoded from the schema stored in the file);
//  - files written there are read here (chunked and unchunked).

#include <filesystem>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <zlib.h>

#include "hanzo/fusion/io/mcap.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "io/node_runner.hpp"
#include "msgs/test_messages.hpp"

namespace hanzo::fusion::io {
namespace {

namespace fixtures = msgs::testing;

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / fmt::format("hanzo_conformance_{}_{}.mcap", name, ::getpid())).string();
}

uint32_t crc_of(std::string_view data) {
  return static_cast<uint32_t>(::crc32(0, reinterpret_cast<const Bytef*>(data.data()), static_cast<uInt>(data.size())));
}

class WrittenHereReadThere : public ::testing::TestWithParam<mcap::Compression> {};

TEST_P(WrittenHereReadThere, FoxgloveReadsEveryMessageAndChecksEveryCrc) {
  const std::string path = temp_path(std::string("here_") + mcap::compression_name(GetParam()));
  SensorLogWriterConfig config;
  config.mcap.compression = GetParam();
  config.mcap.chunk_size = 2048;  // several chunks
  {
    auto writer = SensorLogWriter::open(path, config);
    ASSERT_TRUE(writer.ok());
    for (int i = 0; i < 20; ++i) {
      msgs::ImuMessage imu = fixtures::imu();
      imu.timestamp += Duration::from_milliseconds(10 * i);
      ASSERT_TRUE((*writer)->write("/imu", imu).ok());
      if (i % 5 == 0) {
        msgs::PointCloudMessage cloud = fixtures::point_cloud();
        cloud.timestamp += Duration::from_milliseconds(10 * i + 1);
        ASSERT_TRUE((*writer)->write("/lidar", cloud).ok());
      }
    }
    ASSERT_TRUE((*writer)->write("/gnss", fixtures::gnss()).ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  // What our reader sees, to compare with what Foxglove's sees.
  auto reader = mcap::McapReader::open(path);
  ASSERT_TRUE(reader.ok());
  std::vector<nlohmann::json> ours;
  mcap::MessageIterator it = (*reader)->messages();
  mcap::MessageView view;
  while (*it.next(view)) {
    ours.push_back({{"topic", view.channel->topic}, {"logTime", std::to_string(view.log_time)},
                    {"crc32", crc_of(view.data)}, {"size", view.data.size()}});
  }

  const nlohmann::json theirs = test::run_node("mcap_read.mjs", path);
  ASSERT_FALSE(theirs.is_null());
  EXPECT_EQ(theirs["header"]["library"], "hanzo-fusion");
  EXPECT_EQ(theirs["statistics"]["messageCount"], "30");  // 25 + Foxglove mirrors of 4 clouds and 1 fix
  EXPECT_EQ(theirs["chunkIndexes"].get<std::size_t>(), (*reader)->chunk_indexes().size());
  EXPECT_GT(theirs["chunkIndexes"].get<std::size_t>(), 1u);
  EXPECT_THAT(theirs["metadataIndexes"], ::testing::Contains("hanzo-fusion"));
  ASSERT_EQ(theirs["messages"].size(), ours.size());
  for (std::size_t i = 0; i < ours.size(); ++i) {
    for (const char* key : {"topic", "logTime", "crc32", "size"}) EXPECT_EQ(theirs["messages"][i][key], ours[i][key]) << i << key;
  }
  EXPECT_EQ(theirs["recordCounts"]["Chunk"].get<std::size_t>(), (*reader)->chunk_indexes().size());
  EXPECT_EQ(theirs["dataSectionCrc"]["stored"], theirs["dataSectionCrc"]["computed"]);
  EXPECT_NE(theirs["dataSectionCrc"]["stored"], 0);
  // protobufjs decoded our payloads from the FileDescriptorSet in the file.
  EXPECT_EQ(theirs["decoded"]["/imu"]["timestamp_ns"], std::to_string(fixtures::imu().timestamp.nanoseconds()));
  EXPECT_EQ(theirs["decoded"]["/gnss"]["latitude"], fixtures::gnss().latitude);
  EXPECT_EQ(theirs["decoded"]["/lidar"]["packed_points"].size(), 3 * fixtures::point_cloud().points.size());
  EXPECT_EQ(theirs["decoded"]["/lidar/foxglove"]["point_stride"], 24);
  std::filesystem::remove(path);
}

INSTANTIATE_TEST_SUITE_P(AllCompressions, WrittenHereReadThere,
                         ::testing::Values(mcap::Compression::kNone, mcap::Compression::kLz4, mcap::Compression::kZstd));

class WrittenThereReadHere : public ::testing::TestWithParam<std::string> {};

TEST_P(WrittenThereReadHere, EveryMessageComesBackInTimeOrder) {
  const std::string path = temp_path("there_" + GetParam());
  const nlohmann::json written = test::run_node("mcap_write.mjs", path + " " + GetParam());
  ASSERT_FALSE(written.is_null());
  std::vector<nlohmann::json> expected = written["written"];
  std::stable_sort(expected.begin(), expected.end(), [](const nlohmann::json& a, const nlohmann::json& b) {
    return std::stoull(a["logTime"].get<std::string>()) < std::stoull(b["logTime"].get<std::string>());
  });

  auto reader = mcap::McapReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_FALSE((*reader)->warning());
  EXPECT_EQ((*reader)->library(), "@mcap/core conformance");
  EXPECT_EQ((*reader)->channel_by_topic("/b")->metadata.at("k"), "/b");
  ASSERT_EQ((*reader)->metadata().size(), 1u);
  EXPECT_EQ((*reader)->metadata()[0].values.at("writer"), "@mcap/core");
  mcap::MessageIterator it = (*reader)->messages();
  mcap::MessageView view;
  std::size_t i = 0;
  for (auto more = it.next(view); more.ok() && *more; more = it.next(view), ++i) {
    ASSERT_LT(i, expected.size());
    EXPECT_EQ(view.channel->topic, expected[i]["topic"]) << i;
    EXPECT_EQ(std::to_string(view.log_time), expected[i]["logTime"]) << i;
    EXPECT_EQ(view.sequence, expected[i]["sequence"]) << i;
    EXPECT_EQ(crc_of(view.data), expected[i]["crc32"]) << i;
    EXPECT_EQ(view.schema->encoding, "jsonschema");
  }
  EXPECT_EQ(i, expected.size());
  auto report = (*reader)->verify();
  ASSERT_TRUE(report.ok()) << report.error().message;
  EXPECT_TRUE(report->data_section_crc_checked);  // @mcap/core's data CRC agrees with ours
  EXPECT_EQ(report->messages, expected.size());
  std::filesystem::remove(path);
}

INSTANTIATE_TEST_SUITE_P(ChunkedAndUnchunked, WrittenThereReadHere, ::testing::Values("chunked", "unchunked"));

}  // namespace
}  // namespace hanzo::fusion::io
