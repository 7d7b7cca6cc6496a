#include "hanzo/fusion/io/sensor_log.hpp"

#include <filesystem>
#include <string>

#include <unistd.h>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/dynamic_message.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/msgs/convert.hpp"
#include "hanzo/fusion/v1/sensors.pb.h"
#include "msgs/test_messages.hpp"

namespace hanzo::fusion::io {
namespace {

using ::testing::HasSubstr;
namespace fixtures = msgs::testing;

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("hanzo_sensor_log_test_" + std::to_string(::getpid()) + "_" + name + ".mcap")).string();
}

template <typename T>
T shifted(T message, int64_t ms) {
  message.timestamp += Duration::from_milliseconds(ms);
  return message;
}

TEST(SensorLog, EveryMessageTypeRoundTripsBitIdentical) {
  const std::string path = temp_path("all_types");
  const std::vector<std::pair<std::string, msgs::SensorMessage>> written = {
      {"/imu", fixtures::imu()},
      {"/lidar", shifted(fixtures::point_cloud(), 1)},
      {"/camera", shifted(fixtures::image(), 2)},
      {"/gnss", shifted(fixtures::gnss(), 3)},
      {"/wheels", shifted(fixtures::wheel_odometry(), 4)},
      {"/radar", shifted(fixtures::radar(), 5)},
      {"/imu", shifted(fixtures::imu(), 6)},
  };
  {
    auto writer = SensorLogWriter::open(path);
    ASSERT_TRUE(writer.ok()) << writer.error().message;
    for (const auto& [topic, message] : written) ASSERT_TRUE((*writer)->write(topic, message).ok()) << topic;
    ASSERT_TRUE((*writer)->write("/pose", shifted(fixtures::pose_estimate(), 7)).ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto reader = SensorLogReader::open(path);
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  // 7 topics + the Foxglove mirrors of /lidar, /camera, /gnss and /pose (skipped by this reader).
  EXPECT_EQ((*reader)->mcap().channels().size(), 11u);
  EXPECT_EQ((*reader)->mcap().channel_by_topic("/lidar/foxglove")->metadata.at("mirror_of"), "/lidar");
  EXPECT_EQ((*reader)->mcap().channel_by_topic("/lidar")->metadata.at("modality"), "point_cloud");
  EXPECT_EQ((*reader)->mcap().channel_by_topic("/lidar")->metadata.at("sensor"), "lidar");
  LogEntry entry;
  std::size_t i = 0;
  for (auto more = (*reader)->next(entry); more.ok() && *more; more = (*reader)->next(entry), ++i) {
    if (i == written.size()) {
      const auto& pose = std::get<msgs::PoseEstimate>(entry.message);
      EXPECT_EQ(msgs::to_proto(pose).SerializeAsString(), msgs::to_proto(shifted(fixtures::pose_estimate(), 7)).SerializeAsString());
      continue;
    }
    ASSERT_LT(i, written.size());
    EXPECT_EQ(entry.topic, written[i].first);
    const auto& message = std::get<msgs::SensorMessage>(entry.message);
    EXPECT_EQ(entry.log_time, msgs::timestamp_of(written[i].second));
    EXPECT_EQ(message.index(), written[i].second.index());
    // Same wire bytes as the original message.
    std::visit([&](const auto& typed) {
      const auto& original = std::get<std::decay_t<decltype(typed)>>(written[i].second);
      EXPECT_EQ(msgs::to_proto(typed).SerializeAsString(), msgs::to_proto(original).SerializeAsString()) << entry.topic;
    }, message);
  }
  EXPECT_EQ(i, written.size() + 1);
  EXPECT_EQ((*reader)->skipped_messages(), 4u);
  std::filesystem::remove(path);
}

TEST(SensorLog, SchemaIsAFileDescriptorSetOtherToolsCanDecodeWith) {
  const std::string path = temp_path("schema");
  {
    auto writer = SensorLogWriter::open(path);
    ASSERT_TRUE(writer.ok());
    ASSERT_TRUE((*writer)->write("/imu", fixtures::imu()).ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto reader = mcap::McapReader::open(path);
  ASSERT_TRUE(reader.ok());
  const mcap::Schema& schema = (*reader)->schemas().begin()->second;
  EXPECT_EQ(schema.name, "hanzo.fusion.v1.ImuMessage");
  EXPECT_EQ(schema.encoding, "protobuf");
  // Build a fresh descriptor pool from the schema alone, as a generic tool would, and decode.
  google::protobuf::FileDescriptorSet set;
  ASSERT_TRUE(set.ParseFromString(schema.data));
  google::protobuf::DescriptorPool pool;
  for (const auto& file : set.file()) ASSERT_NE(pool.BuildFile(file), nullptr) << file.name();
  const google::protobuf::Descriptor* descriptor = pool.FindMessageTypeByName(schema.name);
  ASSERT_NE(descriptor, nullptr);
  google::protobuf::DynamicMessageFactory factory(&pool);
  std::unique_ptr<google::protobuf::Message> message(factory.GetPrototype(descriptor)->New());
  mcap::MessageIterator it = (*reader)->messages();
  mcap::MessageView view;
  ASSERT_TRUE(*it.next(view));
  ASSERT_TRUE(message->ParseFromArray(view.data.data(), static_cast<int>(view.data.size())));
  const auto* field = descriptor->FindFieldByName("timestamp_ns");
  EXPECT_EQ(message->GetReflection()->GetUInt64(*message, field), static_cast<uint64_t>(fixtures::imu().timestamp.nanoseconds()));
  EXPECT_EQ(view.channel->message_encoding, "protobuf");
  std::filesystem::remove(path);
}

TEST(SensorLog, InvalidMessagesAreRejectedAndNothingIsWritten) {
  const std::string path = temp_path("invalid");
  auto writer = SensorLogWriter::open(path);
  ASSERT_TRUE(writer.ok());
  msgs::ImuMessage bad = fixtures::imu();
  bad.angular_velocity.x() = std::nan("");
  const Status status = (*writer)->write("/imu", bad);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(status.error().message, HasSubstr("/imu: "));
  EXPECT_THAT(status.error().message, HasSubstr("angular_velocity.x"));
  EXPECT_EQ((*writer)->statistics().message_count, 0u);
  ASSERT_TRUE((*writer)->write("/imu", fixtures::imu()).ok());
  ASSERT_TRUE((*writer)->close().ok());
  auto reader = SensorLogReader::open(path);
  ASSERT_TRUE(reader.ok());
  EXPECT_EQ((*reader)->mcap().statistics().message_count, 1u);
  std::filesystem::remove(path);
}

TEST(SensorLog, UndecodablePayloadIsAnErrorAndReadingContinues) {
  const std::string path = temp_path("undecodable");
  {
    auto writer = mcap::McapWriter::open(path);
    ASSERT_TRUE(writer.ok());
    const google::protobuf::Descriptor& imu = *v1::ImuMessage::descriptor();
    const uint16_t schema = *(*writer)->add_schema(imu.full_name(), "protobuf", file_descriptor_set(imu));
    const uint16_t channel = *(*writer)->add_channel(schema, "/imu", "protobuf");
    ASSERT_TRUE((*writer)->write(channel, 10, 10, "\xff\xff\xff").ok());  // not protobuf
    ASSERT_TRUE((*writer)->write(channel, 20, 20, msgs::to_proto(fixtures::imu()).SerializeAsString()).ok());
    const uint16_t other = *(*writer)->add_channel(0, "/debug", "json");
    ASSERT_TRUE((*writer)->write(other, 15, 15, "{}").ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto reader = SensorLogReader::open(path);
  ASSERT_TRUE(reader.ok());
  LogEntry entry;
  auto first = (*reader)->next(entry);
  ASSERT_FALSE(first.ok());
  EXPECT_THAT(first.error().message, HasSubstr("/imu at 10 ns: payload is not a valid hanzo.fusion.v1.ImuMessage"));
  auto second = (*reader)->next(entry);
  ASSERT_TRUE(second.ok() && *second);
  EXPECT_EQ((*reader)->skipped_messages(), 1u);  // the json channel
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace hanzo::fusion::io
