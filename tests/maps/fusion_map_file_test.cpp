#include "hanzo/fusion/maps/fusion_map_file.hpp"

#include <filesystem>

#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "map_fixtures.hpp"

namespace hanzo::fusion::maps {
namespace {

using ::testing::HasSubstr;

TEST(FusionMapFile, EveryLayerRoundTripsExactlyThroughManyChunks) {
  const msgs::FusionMap map = testing_maps::full_map();
  for (const int level : {0, 3}) {
    FusionMapFileConfig config;
    config.chunk_bytes = 1000;  // forces dozens of chunks per layer
    config.compression_level = level;
    auto bytes = serialize_fusion_map(map, config);
    ASSERT_TRUE(bytes.ok()) << bytes.error().message;
    auto decoded = parse_fusion_map(*bytes);
    ASSERT_TRUE(decoded.ok()) << decoded.error().message;
    testing_maps::expect_same(*decoded, map);
  }
}

TEST(FusionMapFile, MetadataComesFromTheFirstChunkAlone) {
  const msgs::FusionMap map = testing_maps::full_map();
  const std::string path = testing_maps::temp_path("metadata.fmap");
  ASSERT_TRUE(write_fusion_map(path, map));
  auto metadata = read_fusion_map_metadata(path);
  ASSERT_TRUE(metadata.ok()) << metadata.error().message;
  EXPECT_EQ(metadata->map_id, map.map_id);
  EXPECT_EQ(metadata->version, map.version);
  EXPECT_EQ(metadata->provenance.input_logs.size(), 1u);
  EXPECT_FALSE(metadata->points.has_value());
  EXPECT_FALSE(metadata->occupancy.has_value());
  auto whole = read_fusion_map(path);
  ASSERT_TRUE(whole.ok()) << whole.error().message;
  testing_maps::expect_same(*whole, map);
  std::filesystem::remove(path);
}

TEST(FusionMapFile, EmptyLayersKeepTheirPresence) {
  msgs::FusionMap map;
  map.map_id = "empty";
  map.points = msgs::PointLayer{};
  map.mesh = msgs::MeshLayer{};
  auto bytes = serialize_fusion_map(map);
  ASSERT_TRUE(bytes.ok());
  auto decoded = parse_fusion_map(*bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.error().message;
  EXPECT_TRUE(decoded->points.has_value());
  EXPECT_TRUE(decoded->mesh.has_value());
  EXPECT_FALSE(decoded->tsdf.has_value());
}

TEST(FusionMapFile, AFutureFormatVersionIsRejected) {
  auto bytes = serialize_fusion_map(testing_maps::full_map());
  ASSERT_TRUE(bytes.ok());
  std::string future = *bytes;
  future[8] = 2;  // the header's format_version
  auto decoded = parse_fusion_map(future, "future.fmap");
  ASSERT_FALSE(decoded.ok());
  EXPECT_THAT(decoded.error().message, HasSubstr("future.fmap: unsupported FusionMap format_version 2"));
  EXPECT_EQ(decoded.error().field, "format_version");

  // A map that claims version 2 inside is refused by the writer and by the reader.
  msgs::FusionMap map = testing_maps::full_map();
  map.format_version = 2;
  EXPECT_THAT(serialize_fusion_map(map).error().message, HasSubstr("format_version"));
}

TEST(FusionMapFile, DamagedFilesAreRejectedNamingTheDamage) {
  auto written = serialize_fusion_map(testing_maps::full_map(), FusionMapFileConfig{.chunk_bytes = 4000});
  ASSERT_TRUE(written.ok());
  const std::string& bytes = *written;

  EXPECT_THAT(parse_fusion_map("hello world, not a map").error().message, HasSubstr("not a FusionMap file"));
  EXPECT_THAT(parse_fusion_map(bytes.substr(0, bytes.size() - 20)).error().message, HasSubstr("truncated"));
  EXPECT_THAT(parse_fusion_map(bytes.substr(0, bytes.size() / 2)).error().message, HasSubstr("truncated"));
  EXPECT_THAT(parse_fusion_map(bytes + "xx").error().message, HasSubstr("unexpected bytes after the end record"));

  std::string flipped = bytes;
  flipped[16 + 24 + 5] ^= 0x40;  // inside the first chunk's stored bytes
  EXPECT_THAT(parse_fusion_map(flipped).error().message, HasSubstr("checksum"));

  std::string huge = bytes;
  huge[16 + 8 + 3] = 0x7f;  // the first chunk's uncompressed size: > 2 GB
  EXPECT_THAT(parse_fusion_map(huge).error().message, HasSubstr("announces"));

  EXPECT_FALSE(read_fusion_map("/nonexistent/map.fmap").ok());
}

TEST(FusionMapFile, InvalidMapsAreNotWritten) {
  msgs::FusionMap map = testing_maps::full_map();
  map.occupancy->occupancy[3] = 1.5f;
  const auto result = serialize_fusion_map(map);
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(result.error().message, HasSubstr("occupancy"));
}

}  // namespace
}  // namespace hanzo::fusion::maps
