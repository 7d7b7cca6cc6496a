// The Foxglove mirror channels of the sensor log, checked against Foxglove's published schemas
// (@foxglove/schemas, run with node): every field we declare has the official number, type and
// label, and Foxglove's definitions decode our payloads to the values we wrote.

#include <filesystem>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/io/sensor_log.hpp"
#include "io/node_runner.hpp"
#include "msgs/test_messages.hpp"

namespace hanzo::fusion::io {
namespace {

namespace fixtures = msgs::testing;

TEST(FoxgloveMirror, OfficialSchemasDecodeEveryMirrorChannel) {
  const std::string path =
      (std::filesystem::temp_directory_path() / fmt::format("hanzo_foxglove_mirror_{}.mcap", ::getpid())).string();
  msgs::ImageMessage depth = fixtures::image();
  depth.encoding = msgs::ImageEncoding::kDepth16;
  depth.data.resize(depth.width * depth.height * 2);
  {
    auto writer = SensorLogWriter::open(path);
    ASSERT_TRUE(writer.ok());
    ASSERT_TRUE((*writer)->write("/pose", fixtures::pose_estimate()).ok());
    ASSERT_TRUE((*writer)->write("/lidar", fixtures::point_cloud()).ok());
    ASSERT_TRUE((*writer)->write("/gnss", fixtures::gnss(), "gnss_antenna").ok());
    ASSERT_TRUE((*writer)->write("/camera", fixtures::image()).ok());
    ASSERT_TRUE((*writer)->write("/depth", depth).ok());
    ASSERT_TRUE((*writer)->write("/imu", fixtures::imu()).ok());  // no Foxglove schema: not mirrored
    ASSERT_TRUE((*writer)->close().ok());
  }
  const nlohmann::json theirs = test::run_node("foxglove_schemas.mjs", path);
  ASSERT_FALSE(theirs.is_null());
  EXPECT_TRUE(theirs["mismatches"].empty()) << theirs["mismatches"].dump();
  EXPECT_GE(theirs["fieldsCompared"].get<int>(), 25);
  const nlohmann::json& channels = theirs["channels"];
  ASSERT_EQ(channels.size(), 5u) << channels.dump();
  EXPECT_FALSE(channels.contains("/imu/foxglove"));

  const nlohmann::json& pose = channels["/pose/foxglove"];
  EXPECT_EQ(pose["schema"], "foxglove.PoseInFrame");
  EXPECT_EQ(pose["mirror_of"], "/pose");
  const msgs::PoseEstimate expected_pose = fixtures::pose_estimate();
  const int64_t ns = expected_pose.timestamp.nanoseconds();
  EXPECT_EQ(pose["first"]["timestamp"]["seconds"], std::to_string(ns / 1'000'000'000));
  EXPECT_EQ(pose["first"]["timestamp"]["nanos"], ns % 1'000'000'000);
  EXPECT_EQ(pose["first"]["frame_id"], "world");
  EXPECT_EQ(pose["first"]["pose"]["position"]["y"], expected_pose.T_world_body.position.y());
  EXPECT_EQ(pose["first"]["pose"]["orientation"]["w"], expected_pose.T_world_body.orientation.w());

  const nlohmann::json& cloud = channels["/lidar/foxglove"];
  EXPECT_EQ(cloud["schema"], "foxglove.PointCloud");
  EXPECT_EQ(cloud["first"]["point_stride"], 24);
  ASSERT_EQ(cloud["first_points"].size(), 3u);
  const msgs::PointCloudMessage expected_cloud = fixtures::point_cloud();
  for (int i = 0; i < 3; ++i) {
    const nlohmann::json& point = cloud["first_points"][i];
    EXPECT_EQ(point["x"].get<float>(), expected_cloud.points[i].x());
    EXPECT_EQ(point["y"].get<float>(), expected_cloud.points[i].y());
    EXPECT_EQ(point["z"].get<float>(), expected_cloud.points[i].z());
    EXPECT_EQ(point["intensity"].get<float>(), expected_cloud.intensities[i]);
    EXPECT_EQ(point["ring"], expected_cloud.ring_ids[i]);
    EXPECT_NEAR(point["time"].get<double>(), (expected_cloud.point_timestamps[i] - expected_cloud.timestamp).seconds(), 1e-9);
  }

  const nlohmann::json& fix = channels["/gnss/foxglove"];
  EXPECT_EQ(fix["schema"], "foxglove.LocationFix");
  EXPECT_EQ(fix["first"]["frame_id"], "gnss_antenna");
  EXPECT_EQ(fix["first"]["latitude"], fixtures::gnss().latitude);
  EXPECT_EQ(fix["first"]["position_covariance_type"], "KNOWN");
  EXPECT_EQ(fix["first"]["position_covariance"][4], (*fixtures::gnss().position_covariance)(1, 1));

  const nlohmann::json& image = channels["/camera/foxglove"];
  EXPECT_EQ(image["schema"], "foxglove.RawImage");
  EXPECT_EQ(image["first"]["encoding"], "rgb8");
  EXPECT_EQ(image["first"]["step"], 8 * 3);
  EXPECT_EQ(image["first"]["data"], fmt::format("{} bytes", 8 * 4 * 3));
  EXPECT_EQ(channels["/depth/foxglove"]["first"]["encoding"], "16UC1");
  std::filesystem::remove(path);
}

// Images stored as JPEG / PNG are mirrored as the same file in foxglove.CompressedImage.
TEST(FoxgloveMirror, CompressedImagesAreMirroredAsTheFileItself) {
  const std::string path =
      (std::filesystem::temp_directory_path() / fmt::format("hanzo_foxglove_compressed_{}.mcap", ::getpid())).string();
  SensorLogWriterConfig config;
  config.image_compression = ImageCompression::kJpeg;
  {
    auto writer = SensorLogWriter::open(path, config);
    ASSERT_TRUE(writer.ok());
    ASSERT_TRUE((*writer)->write("/camera", fixtures::image()).ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  const nlohmann::json theirs = test::run_node("foxglove_schemas.mjs", path);
  ASSERT_FALSE(theirs.is_null());
  EXPECT_TRUE(theirs["mismatches"].empty()) << theirs["mismatches"].dump();
  const nlohmann::json& image = theirs["channels"]["/camera/foxglove"];
  EXPECT_EQ(image["schema"], "foxglove.CompressedImage");
  EXPECT_EQ(image["first"]["format"], "jpeg");
  EXPECT_EQ(image["first"]["frame_id"], fixtures::image().frame_id);
  EXPECT_EQ(image["mirror_of"], "/camera");
  std::filesystem::remove(path);
}

TEST(FoxgloveMirror, CanBeLeftOut) {
  const std::string path =
      (std::filesystem::temp_directory_path() / fmt::format("hanzo_foxglove_off_{}.mcap", ::getpid())).string();
  SensorLogWriterConfig config;
  config.foxglove_channels = false;
  {
    auto writer = SensorLogWriter::open(path, config);
    ASSERT_TRUE(writer.ok());
    ASSERT_TRUE((*writer)->write("/lidar", fixtures::point_cloud()).ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto reader = SensorLogReader::open(path);
  ASSERT_TRUE(reader.ok());
  EXPECT_EQ((*reader)->mcap().channels().size(), 1u);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace hanzo::fusion::io
