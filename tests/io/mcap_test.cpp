#include "hanzo/fusion/io/mcap.hpp"
#include "mcap_compression.hpp"

#include <filesystem>
#include <string>

#include <unistd.h>
#include <fstream>
#include <random>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::io::mcap {
namespace {

using ::testing::HasSubstr;

struct Written {
  std::string topic;
  uint64_t log_time;
  std::string data;
};

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("hanzo_mcap_test_" + std::to_string(::getpid()) + "_" + name + ".mcap")).string();
}

// Three channels at different rates, times jittered so channels interleave and a few messages
// arrive out of order; payload sizes vary (including empty).
std::vector<Written> make_messages(std::size_t count) {
  std::mt19937 rng(42);
  std::uniform_int_distribution<int> size(0, 300);
  std::uniform_int_distribution<int> jitter(-3000, 3000);
  std::vector<Written> messages;
  const char* topics[] = {"/imu", "/gnss", "/lidar"};
  for (std::size_t i = 0; i < count; ++i) {
    Written m;
    m.topic = topics[i % 3];
    m.log_time = 1'700'000'000'000'000'000ULL + i * 10'000 + static_cast<uint64_t>(jitter(rng) + 3000);
    m.data.resize(static_cast<std::size_t>(size(rng)));
    for (char& c : m.data) c = static_cast<char>(rng());
    messages.push_back(std::move(m));
  }
  return messages;
}

void write_file(const std::string& path, const std::vector<Written>& messages, McapWriterConfig config) {
  auto writer = McapWriter::open(path, config);
  ASSERT_TRUE(writer.ok()) << writer.error().message;
  auto schema = (*writer)->add_schema("test.Blob", "protobuf", std::string("\x0a\x03", 2) + "abc");
  ASSERT_TRUE(schema.ok());
  std::map<std::string, uint16_t> channels;
  for (const char* topic : {"/imu", "/gnss", "/lidar"}) {
    auto channel = (*writer)->add_channel(*schema, topic, "protobuf", {{"sensor", topic + 1}});
    ASSERT_TRUE(channel.ok());
    channels[topic] = *channel;
  }
  for (const Written& m : messages) ASSERT_TRUE((*writer)->write(channels[m.topic], m.log_time, m.log_time + 7, m.data).ok());
  ASSERT_TRUE((*writer)->add_metadata({"provenance", {{"source", "unit test"}, {"importer", "none"}}}).ok());
  ASSERT_TRUE((*writer)->close().ok());
}

std::vector<Written> read_all(const McapReader& reader, const ReadOptions& options = {}) {
  std::vector<Written> out;
  MessageIterator it = reader.messages(options);
  MessageView view;
  while (true) {
    auto more = it.next(view);
    EXPECT_TRUE(more.ok()) << more.error().message;
    if (!more.ok() || !*more) break;
    EXPECT_EQ(view.publish_time, view.log_time + 7);
    out.push_back({view.channel->topic, view.log_time, std::string(view.data)});
  }
  return out;
}

// What the reader must return: log-time order, ties in write order.
std::vector<Written> sorted(std::vector<Written> messages) {
  std::stable_sort(messages.begin(), messages.end(), [](const Written& a, const Written& b) { return a.log_time < b.log_time; });
  return messages;
}

void expect_same(const std::vector<Written>& actual, const std::vector<Written>& expected) {
  ASSERT_EQ(actual.size(), expected.size());
  for (std::size_t i = 0; i < actual.size(); ++i) {
    ASSERT_EQ(actual[i].log_time, expected[i].log_time) << i;
    ASSERT_EQ(actual[i].topic, expected[i].topic) << i;
    ASSERT_EQ(actual[i].data, expected[i].data) << i;  // bit-identical payloads
  }
}

class McapRoundTrip : public ::testing::TestWithParam<Compression> {};

TEST_P(McapRoundTrip, EveryMessageComesBackInTimeOrder) {
  const std::string path = temp_path(std::string("roundtrip_") + compression_name(GetParam()));
  const std::vector<Written> messages = make_messages(3000);
  McapWriterConfig config;
  config.compression = GetParam();
  config.chunk_size = 16 * 1024;  // many chunks
  write_file(path, messages, config);

  auto reader = McapReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  EXPECT_FALSE((*reader)->warning());
  EXPECT_EQ((*reader)->library(), "hanzo-fusion");
  EXPECT_EQ((*reader)->channels().size(), 3u);
  ASSERT_EQ((*reader)->schemas().size(), 1u);
  EXPECT_EQ((*reader)->schemas().begin()->second.data, std::string("\x0a\x03", 2) + "abc");
  EXPECT_EQ((*reader)->channel_by_topic("/gnss")->metadata.at("sensor"), "gnss");
  const Statistics& stats = (*reader)->statistics();
  EXPECT_EQ(stats.message_count, 3000u);
  EXPECT_GT(stats.chunk_count, 5u);
  EXPECT_EQ(stats.channel_message_counts.at((*reader)->channel_by_topic("/lidar")->id), 1000u);
  EXPECT_EQ((*reader)->chunk_indexes().size(), stats.chunk_count);
  EXPECT_EQ(stats.message_start_time, sorted(messages).front().log_time);
  EXPECT_EQ(stats.message_end_time, sorted(messages).back().log_time);
  ASSERT_EQ((*reader)->metadata().size(), 1u);
  EXPECT_EQ((*reader)->metadata()[0].values.at("source"), "unit test");
  expect_same(read_all(**reader), sorted(messages));

  auto report = (*reader)->verify();
  ASSERT_TRUE(report.ok()) << report.error().message;
  EXPECT_EQ(report->messages, 3000u);
  EXPECT_TRUE(report->data_section_crc_checked);
  EXPECT_TRUE(report->summary_crc_checked);
  std::filesystem::remove(path);
}

INSTANTIATE_TEST_SUITE_P(AllCompressions, McapRoundTrip,
                         ::testing::Values(Compression::kNone, Compression::kLz4, Compression::kZstd));

TEST(Mcap, SeeksByTimeAndFiltersTopics) {
  const std::string path = temp_path("seek");
  const std::vector<Written> messages = make_messages(3000);
  McapWriterConfig config;
  config.chunk_size = 8 * 1024;
  write_file(path, messages, config);
  auto reader = McapReader::open(path);
  ASSERT_TRUE(reader.ok());
  const std::vector<Written> all = sorted(messages);
  ReadOptions window;
  window.start_time = all[1000].log_time;
  window.end_time = all[1999].log_time;
  std::vector<Written> expected;
  for (const Written& m : all) {
    if (m.log_time >= window.start_time && m.log_time <= window.end_time) expected.push_back(m);
  }
  expect_same(read_all(**reader, window), expected);

  ReadOptions gnss_only;
  gnss_only.topics = {"/gnss"};
  expected.clear();
  for (const Written& m : all) {
    if (m.topic == "/gnss") expected.push_back(m);
  }
  expect_same(read_all(**reader, gnss_only), expected);
  ReadOptions unknown;
  unknown.topics = {"/nothing"};
  EXPECT_TRUE(read_all(**reader, unknown).empty());
  std::filesystem::remove(path);
}

std::string file_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), {}};
}

void put_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

TEST(Mcap, TruncatedFileIsReadUpToTheLastCompleteChunk) {
  const std::string path = temp_path("truncated");
  const std::vector<Written> messages = make_messages(600);
  McapWriterConfig config;
  config.chunk_size = 4 * 1024;
  write_file(path, messages, config);
  const std::string full = file_bytes(path);
  auto complete = McapReader::open(path);
  ASSERT_TRUE(complete.ok());
  const std::vector<ChunkIndex> chunks = (*complete)->chunk_indexes();
  ASSERT_GT(chunks.size(), 4u);

  // Cut in the middle of the 4th chunk: the first three chunks survive.
  const std::string cut_path = temp_path("truncated_cut");
  put_bytes(cut_path, full.substr(0, chunks[3].chunk_start_offset + chunks[3].chunk_length / 2));
  auto reader = McapReader::open(cut_path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  ASSERT_TRUE((*reader)->warning());
  EXPECT_THAT(*(*reader)->warning(), HasSubstr("truncated"));
  EXPECT_EQ((*reader)->chunk_indexes().size(), 3u);
  const std::vector<Written> recovered = read_all(**reader);
  EXPECT_EQ(recovered.size(), (*reader)->statistics().message_count);
  EXPECT_GT(recovered.size(), 0u);
  EXPECT_LT(recovered.size(), messages.size());
  // Every recovered message is one that was written, bit for bit.
  std::multimap<uint64_t, std::string> written;
  for (const Written& m : messages) written.emplace(m.log_time, m.data);
  for (const Written& m : recovered) {
    auto [begin, end] = written.equal_range(m.log_time);
    EXPECT_TRUE(std::any_of(begin, end, [&](const auto& entry) { return entry.second == m.data; }));
  }
  EXPECT_FALSE((*reader)->verify().ok());  // verify() insists on a complete file

  // Every cut point: opening either fails with a message or succeeds; reading never crashes.
  for (std::size_t size = 0; size < full.size(); size += 97) {
    put_bytes(cut_path, full.substr(0, size));
    auto cut = McapReader::open(cut_path);
    if (!cut.ok()) {
      EXPECT_FALSE(cut.error().message.empty());
      continue;
    }
    MessageIterator it = (*cut)->messages();
    MessageView view;
    std::size_t n = 0;
    for (auto more = it.next(view); more.ok() && *more; more = it.next(view)) ++n;
    EXPECT_LE(n, messages.size());
  }
  std::filesystem::remove(path);
  std::filesystem::remove(cut_path);
}

TEST(Mcap, CorruptionGivesAClearError) {
  const std::string path = temp_path("corrupt");
  McapWriterConfig config;
  config.compression = Compression::kNone;  // so a flipped byte reaches the CRC check
  config.chunk_size = 4 * 1024;
  write_file(path, make_messages(300), config);
  auto reader = McapReader::open(path);
  ASSERT_TRUE(reader.ok());
  const ChunkIndex chunk = (*reader)->chunk_indexes()[1];
  std::string bytes = file_bytes(path);
  bytes[chunk.chunk_start_offset + chunk.chunk_length - 10] ^= 0x5A;  // inside a message payload
  put_bytes(path, bytes);
  auto corrupted = McapReader::open(path);
  ASSERT_TRUE(corrupted.ok());  // the summary is intact
  MessageIterator it = (*corrupted)->messages();
  MessageView view;
  Result<bool> more = true;
  std::size_t before = 0, after = 0;
  while (more.ok() && *more) {
    more = it.next(view);
    if (more.ok() && *more) ++before;
  }
  ASSERT_FALSE(more.ok());
  EXPECT_THAT(more.error().message, HasSubstr(fmt::format("chunk at byte {}: CRC mismatch", chunk.chunk_start_offset)));
  // The rest of the file is still read: only the corrupted chunk's messages are lost.
  for (more = it.next(view); more.ok() && *more; more = it.next(view)) ++after;
  ASSERT_TRUE(more.ok());
  const uint64_t in_chunk = (*reader)->statistics().message_count - before - after;
  EXPECT_GT(in_chunk, 0u);
  EXPECT_GT(after, 0u);
  EXPECT_EQ(before + after + in_chunk, 300u);
  EXPECT_THAT((*corrupted)->verify().error().message, HasSubstr("CRC mismatch"));

  // A flipped byte in the summary fails at open.
  bytes = file_bytes(path);
  bytes[bytes.size() - 60] ^= 0x01;
  put_bytes(path, bytes);
  auto bad_summary = McapReader::open(path);
  ASSERT_FALSE(bad_summary.ok());
  EXPECT_THAT(bad_summary.error().message, HasSubstr("summary CRC mismatch"));
  std::filesystem::remove(path);
}

TEST(Mcap, RejectsFilesThatAreNotMcapVersionZero) {
  const std::string path = temp_path("bad_magic");
  put_bytes(path, "this is not an mcap file at all");
  EXPECT_THAT(McapReader::open(path).error().message, HasSubstr("not an MCAP file (bad magic bytes)"));
  put_bytes(path, std::string("\x89MCAP1\r\n", 8) + std::string(40, '\0'));
  EXPECT_THAT(McapReader::open(path).error().message, HasSubstr("unsupported MCAP major version '1'"));
  put_bytes(path, "");
  EXPECT_THAT(McapReader::open(path).error().message, HasSubstr("too short"));
  EXPECT_THAT(McapReader::open("/nonexistent/log.mcap").error().message, HasSubstr("cannot open file"));
  std::filesystem::remove(path);
}

TEST(Mcap, WriterRejectsMisuse) {
  const std::string path = temp_path("misuse");
  auto writer = McapWriter::open(path);
  ASSERT_TRUE(writer.ok());
  EXPECT_THAT((*writer)->add_channel(5, "/x", "protobuf").error().message, HasSubstr("unknown schema 5"));
  auto channel = (*writer)->add_channel(0, "/x", "json");
  ASSERT_TRUE(channel.ok());
  EXPECT_EQ(*(*writer)->add_channel(0, "/x", "json"), *channel);  // same registration
  EXPECT_THAT((*writer)->add_channel(0, "/x", "cbor").error().message, HasSubstr("already registered"));
  EXPECT_THAT((*writer)->write(9, 1, 1, "x").error().message, HasSubstr("unknown channel 9"));
  ASSERT_TRUE((*writer)->close().ok());
  EXPECT_THAT((*writer)->write(*channel, 1, 1, "x").error().message, HasSubstr("closed"));
  auto reader = McapReader::open(path);
  ASSERT_TRUE(reader.ok());
  EXPECT_EQ((*reader)->statistics().message_count, 0u);
  EXPECT_TRUE((*reader)->verify().ok());
  EXPECT_THAT(McapWriter::open("/nonexistent/dir/x.mcap").error().message, HasSubstr("cannot create file"));
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace hanzo::fusion::io::mcap

namespace hanzo::fusion::io::mcap {
namespace {

// A chunk's declared uncompressed size comes from the file: it is checked before it is
// allocated (found by fuzz/sensor_logs_fuzzer.cpp and fuzz/ros_messages_fuzzer.cpp).
TEST(McapChunks, DeclaredSizesAreCheckedBeforeAllocating) {
  const std::string content(1000, 'a');
  const std::string zstd = compress(Compression::kZstd, 1, content).value();
  EXPECT_EQ(decompress("zstd", zstd, content.size()).value(), content);
  EXPECT_THAT(decompress("zstd", zstd, 1ull << 40).error().message, ::testing::HasSubstr("more than"));
  EXPECT_THAT(decompress("zstd", zstd, 2000).error().message, ::testing::HasSubstr("holds 1000 bytes, its header says 2000"));
  EXPECT_THAT(decompress("zstd", "not zstd", 10).error().message, ::testing::HasSubstr("not a zstd frame"));
  const std::string lz4 = compress(Compression::kLz4, 0, content).value();
  EXPECT_EQ(decompress("lz4", lz4, content.size()).value(), content);
  EXPECT_THAT(decompress("lz4", lz4, 500'000'000).error().message, ::testing::HasSubstr("cannot hold"));
}

}  // namespace
}  // namespace hanzo::fusion::io::mcap
