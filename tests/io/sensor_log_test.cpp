#include "hanzo/fusion/crypto/file_encryption.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"

#include <cmath>
#include <filesystem>
#include <string>

#include <unistd.h>

#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/dynamic_message.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/msgs/convert.hpp"
#include "image_compression.hpp"
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
      {"/range", shifted(fixtures::range(), 5)},
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
  // 8 topics + the Foxglove mirrors of /lidar, /camera, /gnss and /pose (skipped by this reader).
  EXPECT_EQ((*reader)->mcap().channels().size(), 12u);
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

// A textured image (smooth gradients and edges, as a camera sees): JPEG keeps it within a few
// grey levels.
msgs::ImageMessage camera_frame(msgs::ImageEncoding encoding, uint32_t width = 64, uint32_t height = 48) {
  msgs::ImageMessage image = fixtures::image();
  image.encoding = encoding;
  image.width = width;
  image.height = height;
  image.intrinsics.reset();
  const std::size_t channels = msgs::bytes_per_pixel(encoding) / (encoding == msgs::ImageEncoding::kDepth16 ? 2 : 1);
  image.data.resize(std::size_t{width} * height * msgs::bytes_per_pixel(encoding));
  for (uint32_t y = 0; y < height; ++y) {
    for (uint32_t x = 0; x < width; ++x) {
      for (std::size_t c = 0; c < channels; ++c) {
        const int value = ((x / 16 + y / 16) % 2 ? 180 : 60) + static_cast<int>(x + 2 * c);
        const std::size_t index = (std::size_t{y} * width + x) * channels + c;
        if (encoding == msgs::ImageEncoding::kDepth16) {
          reinterpret_cast<uint16_t*>(image.data.data())[index] = static_cast<uint16_t>(value * 37);
        } else {
          image.data[index] = static_cast<uint8_t>(value);
        }
      }
    }
  }
  return image;
}

// Images stored as PNG come back bit-identical, as JPEG within a few grey levels, as what they
// were (encoding, size, intrinsics); depth32f stays raw. Bad files are named.
// The image filter (the privacy filter of `import --privacy`) sees every image before it is
// written, changes only the copy it is given, and an error from it fails the write.
// A log encrypted at rest (crypto/file_encryption.hpp) reads like the plain one with its key in
// HANZO_ENCRYPTION_KEY (or among several, comma-separated); without it the reader says so.
TEST(SensorLog, EncryptedLogsAreReadWithTheKeyFromTheEnvironment) {
  const std::string plain = temp_path("plain"), sealed = temp_path("sealed");
  {
    auto writer = SensorLogWriter::open(plain);
    ASSERT_TRUE(writer.ok());
    ASSERT_TRUE((*writer)->write("/imu", msgs::SensorMessage(fixtures::imu())).ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  const crypto::EncryptionKey key = crypto::EncryptionKey::generate();
  ASSERT_TRUE(crypto::encrypt_file(plain, sealed, key).ok());
  ::unsetenv("HANZO_ENCRYPTION_KEY");
  auto refused = SensorLogReader::open(sealed);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("the file is encrypted; set HANZO_ENCRYPTION_KEY"), std::string::npos);
  const std::string keys = crypto::EncryptionKey::generate().to_hex() + "," + key.to_hex();
  ::setenv("HANZO_ENCRYPTION_KEY", keys.c_str(), 1);
  auto reader = SensorLogReader::open(sealed);
  ::unsetenv("HANZO_ENCRYPTION_KEY");
  ASSERT_TRUE(reader.ok()) << reader.error().message;
  LogEntry entry;
  ASSERT_TRUE((*reader)->next(entry).value());
  EXPECT_EQ(entry.topic, "/imu");
  EXPECT_EQ(std::get<msgs::ImuMessage>(std::get<msgs::SensorMessage>(entry.message)).angular_velocity, fixtures::imu().angular_velocity);
  EXPECT_FALSE((*reader)->next(entry).value());
  std::filesystem::remove(plain);
  std::filesystem::remove(sealed);
}

TEST(SensorLog, ImageFilterRunsBeforeImagesAreWritten) {
  const std::string path = temp_path("filtered");
  const msgs::ImageMessage original = camera_frame(msgs::ImageEncoding::kRgb8);
  int filtered = 0;
  SensorLogWriterConfig config;
  config.image_filter = [&](msgs::ImageMessage& image) -> Status {
    if (image.frame_id == "refuse") return Error("not allowed");
    std::fill(image.data.begin(), image.data.end(), uint8_t{0});
    ++filtered;
    return ok_status();
  };
  {
    auto writer = SensorLogWriter::open(path, config);
    ASSERT_TRUE(writer.ok());
    ASSERT_TRUE((*writer)->write("/camera", original).ok());
    msgs::ImageMessage refused = original;
    refused.frame_id = "refuse";
    const Status error = (*writer)->write("/camera", refused);
    ASSERT_FALSE(error.ok());
    EXPECT_EQ(error.error().message, "/camera: not allowed");
    ASSERT_TRUE((*writer)->close().ok());
  }
  EXPECT_EQ(filtered, 1);
  EXPECT_NE(std::count(original.data.begin(), original.data.end(), uint8_t{0}), static_cast<long>(original.data.size()));
  auto reader = SensorLogReader::open(path);
  ASSERT_TRUE(reader.ok());
  LogEntry entry;
  int images = 0;
  while ((*reader)->next(entry).value()) {
    const auto& image = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>(entry.message));
    EXPECT_EQ(std::count(image.data.begin(), image.data.end(), uint8_t{0}), static_cast<long>(image.data.size()));
    ++images;
  }
  EXPECT_EQ(images, 1);
  std::filesystem::remove(path);
}

TEST(SensorLog, ImagesStoredAsPngOrJpegComeBackAsRawPixels) {
  for (const ImageCompression compression : {ImageCompression::kPng, ImageCompression::kJpeg}) {
    const std::string path = temp_path("images");
    const std::vector<msgs::ImageMessage> images = {camera_frame(msgs::ImageEncoding::kRgb8), camera_frame(msgs::ImageEncoding::kBgr8),
                                                    camera_frame(msgs::ImageEncoding::kMono8), camera_frame(msgs::ImageEncoding::kDepth16),
                                                    fixtures::image()};
    msgs::ImageMessage floats = camera_frame(msgs::ImageEncoding::kMono8);
    floats.encoding = msgs::ImageEncoding::kDepth32f;
    floats.data.assign(std::size_t{floats.width} * floats.height * 4, 0);
    SensorLogWriterConfig config;
    config.image_compression = compression;
    {
      auto writer = SensorLogWriter::open(path, config);
      ASSERT_TRUE(writer.ok());
      for (std::size_t i = 0; i < images.size(); ++i) ASSERT_TRUE((*writer)->write("/camera" + std::to_string(i), images[i]).ok());
      ASSERT_TRUE((*writer)->write("/depth32", floats).ok());
      ASSERT_TRUE((*writer)->close().ok());
    }
    auto reader = SensorLogReader::open(path);
    ASSERT_TRUE(reader.ok());
    LogEntry entry;
    for (std::size_t i = 0; i <= images.size(); ++i) {
      const auto more = (*reader)->next(entry);
      ASSERT_TRUE(more.ok() && *more) << (more.ok() ? "" : more.error().message);
      const auto& image = std::get<msgs::ImageMessage>(std::get<msgs::SensorMessage>(entry.message));
      const msgs::ImageMessage& expected = i < images.size() ? images[i] : floats;
      ASSERT_EQ(image.encoding, expected.encoding);
      ASSERT_EQ(image.width, expected.width);
      ASSERT_EQ(image.height, expected.height);
      EXPECT_EQ(image.intrinsics.has_value(), expected.intrinsics.has_value());
      ASSERT_EQ(image.data.size(), expected.data.size());
      const bool lossless = compression == ImageCompression::kPng || expected.encoding == msgs::ImageEncoding::kDepth16 ||
                            expected.encoding == msgs::ImageEncoding::kDepth32f;
      if (lossless) {
        EXPECT_EQ(image.data, expected.data) << i;
      } else if (expected.width > 8) {  // the tiny fixture image is noise to JPEG
        double difference = 0.0;
        for (std::size_t k = 0; k < image.data.size(); ++k) difference += std::abs(int{image.data[k]} - int{expected.data[k]});
        EXPECT_LT(difference / static_cast<double>(image.data.size()), 4.0) << i;
      }
    }
    std::filesystem::remove(path);
  }

  // A stored file that does not decode, or decodes to another size, is an error naming the topic.
  const std::string path = temp_path("bad_images");
  v1::ImageMessage broken = msgs::to_proto(camera_frame(msgs::ImageEncoding::kRgb8));
  broken.set_compression("png");
  broken.set_data("not a png file");
  v1::ImageMessage wrong_size = compressed_image(camera_frame(msgs::ImageEncoding::kRgb8), ImageCompression::kPng, 90);
  wrong_size.set_width(32);
  v1::ImageMessage unknown = broken;
  unknown.set_compression("webp");
  {
    auto writer = SensorLogWriter::open(path);
    ASSERT_TRUE(writer.ok());
    ASSERT_TRUE((*writer)->write_proto("/broken", broken, Timestamp::from_nanoseconds(10)).ok());
    ASSERT_TRUE((*writer)->write_proto("/wrong_size", wrong_size, Timestamp::from_nanoseconds(20)).ok());
    ASSERT_TRUE((*writer)->write_proto("/unknown", unknown, Timestamp::from_nanoseconds(30)).ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto reader = SensorLogReader::open(path);
  ASSERT_TRUE(reader.ok());
  LogEntry entry;
  for (const char* expected : {"/broken at 10 ns: data: not a readable png file", "/wrong_size at 20 ns: data: the png file holds 64x48",
                               "/unknown at 30 ns: compression 'webp'"}) {
    const auto read = (*reader)->next(entry);
    ASSERT_FALSE(read.ok()) << expected;
    EXPECT_THAT(read.error().message, HasSubstr(expected));
  }
  std::filesystem::remove(path);
}

// Points stored quantized come back within half the resolution; exact ones bit-identical.
TEST(SensorLog, PointsStoredQuantizedComeBackWithinHalfTheResolution) {
  const std::string path = temp_path("quantized");
  SensorLogWriterConfig config;
  config.point_resolution = 0.001;
  const msgs::PointCloudMessage sweep = fixtures::point_cloud();
  {
    auto writer = SensorLogWriter::open(path, config);
    ASSERT_TRUE(writer.ok());
    ASSERT_TRUE((*writer)->write("/lidar", sweep).ok());
    ASSERT_TRUE((*writer)->close().ok());
  }
  auto reader = SensorLogReader::open(path);
  LogEntry entry;
  ASSERT_TRUE(*(*reader)->next(entry));
  const auto& back = std::get<msgs::PointCloudMessage>(std::get<msgs::SensorMessage>(entry.message));
  ASSERT_EQ(back.points.size(), sweep.points.size());
  for (std::size_t i = 0; i < sweep.points.size(); ++i) {
    EXPECT_LE((back.points[i] - sweep.points[i]).cwiseAbs().maxCoeff(), 0.0005f + 1e-6f) << i;
  }
  EXPECT_EQ(back.intensities, sweep.intensities);
  EXPECT_EQ(back.ring_ids, sweep.ring_ids);
  EXPECT_EQ(back.point_timestamps, sweep.point_timestamps);
  std::filesystem::remove(path);
  config.point_resolution = -1.0;
  EXPECT_FALSE(SensorLogWriter::open(path, config).ok());
  config.point_resolution = 0.0;
  config.jpeg_quality = 0;
  EXPECT_FALSE(SensorLogWriter::open(path, config).ok());
}

}  // namespace
}  // namespace hanzo::fusion::io
