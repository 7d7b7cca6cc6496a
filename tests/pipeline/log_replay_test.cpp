// replay_log on logs read only in part: a corrupted chunk is skipped and the rest of the file is
// read; a truncated file ends at its last complete record; either way incomplete() says what
// was lost and how much was read, and a complete log says nothing.

#include <filesystem>
#include <fstream>
#include <iterator>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/io/mcap.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/pipeline/log_replay.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using ::testing::HasSubstr;

// 12 s of the urban vehicle's IMU, GNSS and wheels in small uncompressed chunks.
struct SmallLog {
  sim::Scenario scenario;
  std::string path;
};

SmallLog write_small_log(const std::string& name) {
  SmallLog log{sim::load_scenario("examples/scenarios/urban_vehicle.yaml").value(), (std::filesystem::temp_directory_path() / name).string()};
  std::erase_if(log.scenario.sensors, [](const sim::ScenarioSensor& s) {
    return s.modality != config::SensorModality::kImu && s.modality != config::SensorModality::kGnss &&
           s.modality != config::SensorModality::kWheelOdometry;
  });
  log.scenario.duration = 12.0;
  io::SensorLogWriterConfig config;
  config.mcap.compression = io::mcap::Compression::kNone;  // a flipped byte reaches the CRC check
  config.mcap.chunk_size = 16 * 1024;
  config.foxglove_channels = false;
  auto writer = io::SensorLogWriter::open(log.path, config).value();
  auto simulation = sim::ScenarioSimulation::create(log.scenario).value();
  EXPECT_TRUE(simulation->run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status {
    return writer->write(sensor.topic, message, sensor.name);
  }));
  EXPECT_TRUE(writer->close());
  return log;
}

LogReplaySummary replay(const SmallLog& log, const std::string& path) {
  auto session = Session::create(sim::scenario_fusion_config(log.scenario), sim::scenario_calibration(log.scenario)).value();
  auto reader = io::SensorLogReader::open(path).value();
  return replay_log(*session, *reader);
}

std::string bytes_of(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(file), std::istreambuf_iterator<char>()};
}

void write_bytes(const std::string& path, const std::string& bytes) { std::ofstream(path, std::ios::binary) << bytes; }

TEST(LogReplay, SaysWhatACorruptedOrTruncatedLogLost) {
  const SmallLog log = write_small_log("replay_small.mcap");
  const LogReplaySummary complete = replay(log, log.path);
  EXPECT_EQ(complete.incomplete(), "");
  EXPECT_EQ(complete.records_read, complete.records_in_file);
  EXPECT_GT(complete.messages, 2000u);

  // A flipped byte in a chunk of the first third: that chunk is lost, the rest is read.
  const auto chunks = io::mcap::McapReader::open(log.path).value()->chunk_indexes();
  ASSERT_GT(chunks.size(), 6u);
  const io::mcap::ChunkIndex& chunk = chunks[chunks.size() / 3];
  std::string bytes = bytes_of(log.path);
  bytes[chunk.chunk_start_offset + chunk.chunk_length - 20] ^= 0x5A;
  const std::string corrupted_path = log.path + ".corrupted.mcap";
  write_bytes(corrupted_path, bytes);
  const LogReplaySummary corrupted = replay(log, corrupted_path);
  EXPECT_EQ(corrupted.corrupted_chunks, 1u);
  EXPECT_THAT(corrupted.incomplete(), HasSubstr(fmt::format("1 corrupted chunk skipped ({}: chunk at byte {}: CRC mismatch", corrupted_path,
                                                            chunk.chunk_start_offset)));
  EXPECT_THAT(corrupted.incomplete(), HasSubstr(fmt::format("of {} messages)", complete.records_in_file)));
  EXPECT_LT(corrupted.messages, complete.messages);
  EXPECT_GT(corrupted.messages, complete.messages * 3 / 4);  // only one chunk's worth is lost
  EXPECT_EQ(corrupted.read_until, complete.read_until);     // read to the end

  // Cut at two thirds: the summary is gone; the file is scanned up to its last complete record.
  const std::string truncated_path = log.path + ".truncated.mcap";
  write_bytes(truncated_path, bytes_of(log.path).substr(0, bytes.size() * 2 / 3));
  const LogReplaySummary truncated = replay(log, truncated_path);
  EXPECT_THAT(truncated.incomplete(), HasSubstr("file is truncated"));
  EXPECT_THAT(truncated.incomplete(), HasSubstr("read "));
  EXPECT_LT(truncated.messages, complete.messages);
  for (const std::string& path : {log.path, corrupted_path, truncated_path}) std::filesystem::remove(path);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
