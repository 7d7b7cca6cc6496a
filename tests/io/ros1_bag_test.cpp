// ROS1 bag reading and message conversion on bags built here record by record (bag format
// 2.0), for what test2.bag does not contain: uncompressed and lz4 chunks, NavSatFix,
// PointCloud2, Image, cut-off files and bad input.

#include <cmath>
#include <cstring>
#include <limits>
#include <filesystem>
#include <string>

#include <unistd.h>
#include <fstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <lz4frame.h>

#include "hanzo/fusion/io/ros1_bag.hpp"
#include "hanzo/fusion/msgs/validate.hpp"
#include "hanzo/fusion/io/ros_conversion.hpp"
#include "hanzo/fusion/io/rosbag_import.hpp"

namespace hanzo::fusion::io::ros1 {
namespace {

using ::testing::HasSubstr;
constexpr ros::Serialization kRos1 = ros::Serialization::kRos1;

// ROS1 serialization helpers.
struct Ser {
  std::string out;
  template <typename T>
  Ser& raw(T v) {
    out.append(reinterpret_cast<const char*>(&v), sizeof v);
    return *this;
  }
  Ser& str(const std::string& s) {
    raw(static_cast<uint32_t>(s.size()));
    out += s;
    return *this;
  }
  Ser& header(uint32_t sec, uint32_t nsec, const std::string& frame) { return raw<uint32_t>(0).raw(sec).raw(nsec).str(frame); }
  Ser& f64s(std::initializer_list<double> values) {
    for (double v : values) raw(v);
    return *this;
  }
  Ser& zeros(int count) {
    for (int i = 0; i < count; ++i) raw(0.0);
    return *this;
  }
};

std::string field(const std::string& name, const std::string& value) {
  std::string body = name + "=" + value;
  uint32_t n = static_cast<uint32_t>(body.size());
  return std::string(reinterpret_cast<const char*>(&n), 4) + body;
}
template <typename T>
std::string field_int(const std::string& name, T v) {
  return field(name, std::string(reinterpret_cast<const char*>(&v), sizeof v));
}
std::string record(const std::string& header, const std::string& data) {
  uint32_t h = static_cast<uint32_t>(header.size()), d = static_cast<uint32_t>(data.size());
  return std::string(reinterpret_cast<const char*>(&h), 4) + header + std::string(reinterpret_cast<const char*>(&d), 4) + data;
}
std::string connection(uint32_t id, const std::string& topic, const std::string& type) {
  return record(field_int<uint8_t>("op", 7) + field_int("conn", id) + field("topic", topic),
                field("topic", topic) + field("type", type) + field("md5sum", "0") + field("message_definition", ""));
}
std::string message(uint32_t id, uint32_t sec, const std::string& data) {
  const uint64_t time = static_cast<uint64_t>(sec);  // sec in the low word, nsec 0
  return record(field_int<uint8_t>("op", 2) + field_int("conn", id) + field_int("time", time), data);
}
std::string chunk(const std::string& records, const std::string& compression) {
  std::string data = records;
  if (compression == "lz4") {
    data.resize(LZ4F_compressFrameBound(records.size(), nullptr));
    data.resize(LZ4F_compressFrame(data.data(), data.size(), records.data(), records.size(), nullptr));
  }
  return record(field_int<uint8_t>("op", 5) + field("compression", compression) +
                    field_int("size", static_cast<uint32_t>(records.size())),
                data);
}

std::string imu_data(uint32_t sec) {
  Ser s;
  s.header(sec, 500, "imu_link").f64s({0, 0, 0, 1}).zeros(9).f64s({0.1, 0.2, 0.3}).zeros(9).f64s({0.0, 0.0, 9.81}).zeros(9);
  return s.out;
}

std::string navsatfix_data(int8_t status) {
  Ser s;
  s.header(100, 0, "gps").raw(status).raw<uint16_t>(1).f64s({48.1, 11.5, 520.0}).f64s({1, 0, 0, 0, 1, 0, 0, 0, 4}).raw<uint8_t>(2);
  return s.out;
}

// Two points (one NaN) with x y z float32, intensity float32 (0-255), ring uint16, time float32.
std::string pointcloud_data() {
  Ser s;
  s.header(200, 0, "velodyne").raw<uint32_t>(1).raw<uint32_t>(3).raw<uint32_t>(6);
  const std::vector<std::tuple<std::string, uint32_t, uint8_t>> fields = {
      {"x", 0, 7}, {"y", 4, 7}, {"z", 8, 7}, {"intensity", 12, 7}, {"ring", 16, 4}, {"time", 18, 7}};
  for (const auto& [name, offset, type] : fields) s.str(name).raw(offset).raw(type).raw<uint32_t>(1);
  s.raw<uint8_t>(0).raw<uint32_t>(22).raw<uint32_t>(66);
  Ser points;
  const float nan = std::nanf("");
  for (const auto& [x, intensity, ring, time] : std::vector<std::tuple<float, float, uint16_t, float>>{
           {1.0F, 255.0F, 3, 0.0F}, {nan, 10.0F, 4, 0.05F}, {2.0F, 51.0F, 5, 0.1F}}) {
    points.raw(x).raw(0.5F).raw(-0.25F).raw(intensity).raw(ring).raw(time);
  }
  s.str(points.out).raw<uint8_t>(0);
  return s.out;
}

std::string image_data() {
  Ser s;
  s.header(300, 0, "camera").raw<uint32_t>(2).raw<uint32_t>(3).str("mono8").raw<uint8_t>(0).raw<uint32_t>(4);
  s.str(std::string("\x01\x02\x03\xff\x04\x05\x06\xff", 8));  // 3 pixels + 1 padding byte per row
  return s.out;
}

std::string bag_file(const std::string& body) {
  const std::string header_record = record(field_int<uint8_t>("op", 3) + field_int<uint64_t>("index_pos", 0) +
                                               field_int<uint32_t>("conn_count", 0) + field_int<uint32_t>("chunk_count", 0),
                                           std::string(4000, ' '));
  return "#ROSBAG V2.0\n" + header_record + body;
}

std::string write_temp(const std::string& name, const std::string& bytes) {
  const std::string path = (std::filesystem::temp_directory_path() / ("hanzo_ros1_" + std::to_string(::getpid()) + "_" + name + ".bag")).string();
  std::ofstream(path, std::ios::binary) << bytes;
  return path;
}

TEST(Ros1Bag, ReadsUncompressedAndLz4ChunksInFileOrder) {
  const std::string records1 = connection(0, "/imu", "sensor_msgs/Imu") + message(0, 10, imu_data(10)) + message(0, 11, imu_data(11));
  const std::string records2 = message(0, 12, imu_data(12));
  const std::string path = write_temp("chunks", bag_file(chunk(records1, "none") + chunk(records2, "lz4")));
  std::vector<int64_t> times;
  auto summary = read_bag(path, [&](const BagMessage& m) {
    EXPECT_EQ(m.connection->type, "sensor_msgs/Imu");
    auto imu = ros::imu_from_ros(m.data, kRos1);
    EXPECT_TRUE(imu.ok());
    times.push_back(imu->timestamp.nanoseconds());
    return ok_status();
  });
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_EQ(summary->chunks, 2u);
  EXPECT_EQ(summary->chunk_compressions.at("lz4"), 1u);
  EXPECT_TRUE(summary->complete);
  EXPECT_EQ(times, (std::vector<int64_t>{10'000'000'500, 11'000'000'500, 12'000'000'500}));
  std::filesystem::remove(path);
}

TEST(Ros1Bag, CutOffBagIsReadUpToTheLastCompleteChunk) {
  const std::string first = chunk(connection(0, "/imu", "sensor_msgs/Imu") + message(0, 10, imu_data(10)), "none");
  const std::string second = chunk(message(0, 11, imu_data(11)), "none");
  const std::string full = bag_file(first + second);
  const std::string path = write_temp("cut", full.substr(0, full.size() - 20));
  std::size_t count = 0;
  auto summary = read_bag(path, [&](const BagMessage&) { ++count; return ok_status(); });
  ASSERT_TRUE(summary.ok());
  EXPECT_FALSE(summary->complete);
  EXPECT_EQ(count, 1u);
  std::filesystem::remove(path);
}

TEST(Ros1Bag, RejectsOtherFilesAndVersions) {
  const std::string not_bag = write_temp("not_bag", "hello world, not a bag at all");
  EXPECT_THAT(read_bag(not_bag, [](const BagMessage&) { return ok_status(); }).error().message, HasSubstr("not a ROS bag"));
  const std::string v12 = write_temp("v12", "#ROSBAG V1.2\n....");
  EXPECT_THAT(read_bag(v12, [](const BagMessage&) { return ok_status(); }).error().message,
              HasSubstr("unsupported bag version '1.2'"));
  const std::string bad_chunk = write_temp("bad_chunk", bag_file(record(field_int<uint8_t>("op", 5) + field("compression", "lz4") +
                                                                            field_int<uint32_t>("size", 100), "garbage")));
  EXPECT_THAT(read_bag(bad_chunk, [](const BagMessage&) { return ok_status(); }).error().message, HasSubstr("lz4"));
  const std::string orphan = write_temp("orphan", bag_file(chunk(message(7, 1, "x"), "none")));
  EXPECT_THAT(read_bag(orphan, [](const BagMessage&) { return ok_status(); }).error().message,
              HasSubstr("connection 7 before its definition"));
  for (const auto& p : {not_bag, v12, bad_chunk, orphan}) std::filesystem::remove(p);
}

// Lengths and sizes the file declares are checked before they are allocated: a record longer
// than the rest of the file is a cut-off recording; a bz2 chunk declaring more than 1 GiB is refused.
TEST(Ros1Bag, DeclaredLengthsAreCheckedBeforeAllocating) {
  const std::string first = chunk(connection(0, "/imu", "sensor_msgs/Imu") + message(0, 10, imu_data(10)), "none");
  std::string huge_record(8, '\0');
  const uint32_t header_length = 0xFFFFFFF0u;
  std::memcpy(huge_record.data(), &header_length, 4);
  const std::string path = write_temp("huge", bag_file(first) + huge_record);
  std::size_t count = 0;
  auto summary = read_bag(path, [&](const BagMessage&) { ++count; return ok_status(); });
  ASSERT_TRUE(summary.ok()) << summary.error().message;
  EXPECT_FALSE(summary->complete);
  EXPECT_EQ(count, 1u);
  const std::string bz2 = write_temp("bz2_huge", bag_file(record(field_int<uint8_t>("op", 5) + field("compression", "bz2") +
                                                                     field_int<uint32_t>("size", 0xFFFFFFF0u), "BZh9")));
  EXPECT_THAT(read_bag(bz2, [](const BagMessage&) { return ok_status(); }).error().message, HasSubstr("more than"));
  for (const auto& p : {path, bz2}) std::filesystem::remove(p);
}

TEST(Ros1Conversion, NavSatFixStatusAndCovariance) {
  auto fix = ros::gnss_from_ros(navsatfix_data(0), kRos1);
  ASSERT_TRUE(fix.ok());
  EXPECT_EQ(fix->timestamp.nanoseconds(), 100'000'000'000);
  EXPECT_EQ(fix->fix_type, msgs::GnssFixType::kFix3d);
  EXPECT_DOUBLE_EQ(fix->latitude, 48.1);
  ASSERT_TRUE(fix->position_covariance.has_value());
  EXPECT_EQ((*fix->position_covariance)(2, 2), 4.0);
  EXPECT_EQ(ros::gnss_from_ros(navsatfix_data(-1), kRos1)->fix_type, msgs::GnssFixType::kNoFix);
  EXPECT_EQ(ros::gnss_from_ros(navsatfix_data(2), kRos1)->fix_type, msgs::GnssFixType::kRtkFixed);
  EXPECT_THAT(ros::gnss_from_ros(navsatfix_data(0).substr(0, 30), kRos1).error().message, HasSubstr("NavSatFix: truncated"));
}

// sensor_msgs/Range: an ultrasonic reading, and one with nothing in range (+inf).
TEST(Ros1Conversion, RangeReadings) {
  const auto range_data = [](float reading) {
    Ser s;
    s.header(150, 0, "sonar").raw<uint8_t>(0).raw(0.26F).raw(0.02F).raw(4.0F).raw(reading);
    return s.out;
  };
  auto range = ros::range_from_ros(range_data(1.25F), kRos1);
  ASSERT_TRUE(range.ok()) << range.error().message;
  EXPECT_EQ(range->timestamp.nanoseconds(), 150'000'000'000);
  EXPECT_EQ(range->frame_id, "sonar");
  EXPECT_EQ(range->radiation, msgs::RangeRadiation::kUltrasound);
  EXPECT_EQ(range->field_of_view, 0.26F);
  EXPECT_EQ(range->max_range, 4.0F);
  EXPECT_EQ(range->range, 1.25F);
  EXPECT_TRUE(msgs::validate(*range).ok());
  EXPECT_TRUE(std::isinf(ros::range_from_ros(range_data(std::numeric_limits<float>::infinity()), kRos1)->range));
  EXPECT_THAT(ros::range_from_ros(range_data(1.25F).substr(0, 20), kRos1).error().message, HasSubstr("Range: truncated"));
}

TEST(Ros1Conversion, PointCloud2FieldsScaledAndNanDropped) {
  auto cloud = ros::point_cloud_from_ros(pointcloud_data(), kRos1);
  ASSERT_TRUE(cloud.ok()) << cloud.error().message;
  ASSERT_EQ(cloud->points.size(), 2u);  // the NaN point is dropped
  EXPECT_EQ(cloud->points[1], Eigen::Vector3f(2.0F, 0.5F, -0.25F));
  EXPECT_FLOAT_EQ(cloud->intensities[0], 1.0F);
  EXPECT_FLOAT_EQ(cloud->intensities[1], 0.2F);
  EXPECT_EQ(cloud->ring_ids, (std::vector<uint32_t>{3, 5}));
  EXPECT_NEAR((cloud->point_timestamps[1] - cloud->timestamp).nanoseconds(), 100'000'000, 2);  // 0.1 as float32
  EXPECT_THAT(ros::point_cloud_from_ros(pointcloud_data().substr(0, 60), kRos1).error().message, HasSubstr("truncated"));
}

TEST(Ros1Conversion, ImageRowPaddingIsRemoved) {
  auto image = ros::image_from_ros(image_data(), kRos1);
  ASSERT_TRUE(image.ok()) << image.error().message;
  EXPECT_EQ(image->encoding, msgs::ImageEncoding::kMono8);
  EXPECT_EQ(image->data, (std::vector<uint8_t>{1, 2, 3, 4, 5, 6}));
  std::string yuv = image_data();
  const auto at = yuv.find("mono8");
  yuv.replace(at, 5, "yuv42");
  EXPECT_THAT(ros::image_from_ros(yuv, kRos1).error().message, HasSubstr("encoding 'yuv42' is not supported"));
}

TEST(Ros1Conversion, WheelIntegratorRejectsTimeGoingBack) {
  ros::WheelDistanceIntegrator integrator(0.5);
  ros::OdometryTwist twist;
  twist.stamp = Timestamp::from_nanoseconds(1'000'000'000);
  twist.forward_speed = 1.0;
  twist.yaw_rate = 0.2;
  ASSERT_TRUE(integrator.add(twist).ok());
  twist.stamp = Timestamp::from_nanoseconds(2'000'000'000);
  auto wheel = integrator.add(twist);
  ASSERT_TRUE(wheel.ok());
  EXPECT_DOUBLE_EQ(wheel->left_distance, 0.95);   // (1 - 0.2 * 0.25) m/s for 1 s
  EXPECT_DOUBLE_EQ(wheel->right_distance, 1.05);
  twist.stamp = Timestamp::from_nanoseconds(1'500'000'000);
  EXPECT_THAT(integrator.add(twist).error().message, HasSubstr("not after the previous one"));
}

TEST(RosbagImport, AllTypesWithBadMessagesCountedNotFatal) {
  std::string bad_imu = imu_data(13);
  bad_imu.replace(bad_imu.size() - 9 * 8 - 8, 8, std::string("\x00\x00\x00\x00\x00\x00\xf8\x7f", 8));  // az = NaN
  const std::string records = connection(0, "/imu/data", "sensor_msgs/Imu") + connection(1, "/fix", "sensor_msgs/NavSatFix") +
                              connection(2, "/velodyne_points", "sensor_msgs/PointCloud2") +
                              connection(3, "/camera/image", "sensor_msgs/Image") + connection(4, "/tf", "tf2_msgs/TFMessage") +
                              message(0, 10, imu_data(10)) + message(0, 13, bad_imu) + message(1, 100, navsatfix_data(0)) +
                              message(2, 200, pointcloud_data()) + message(3, 300, image_data()) + message(4, 1, "tf");
  const std::string bag = write_temp("all_types", bag_file(chunk(records, "lz4")));
  const std::string log = (std::filesystem::temp_directory_path() / ("hanzo_ros1_all_types_" + std::to_string(::getpid()) + ".mcap")).string();
  auto writer = SensorLogWriter::open(log);
  ASSERT_TRUE(writer.ok());
  auto report = import_rosbag(bag, **writer, {});
  ASSERT_TRUE(report.ok()) << report.error().message;
  ASSERT_TRUE((*writer)->close().ok());
  ASSERT_EQ(report->topics.size(), 4u);
  std::map<std::string, TopicImportReport> by_topic;
  for (const auto& t : report->topics) by_topic[t.topic] = t;
  EXPECT_EQ(by_topic["/imu"].imported, 1u);
  EXPECT_EQ(by_topic["/imu"].rejected, 1u);
  EXPECT_THAT(by_topic["/imu"].first_rejection, HasSubstr("linear_acceleration.z"));
  EXPECT_EQ(by_topic["/fix"].imported, 1u);
  EXPECT_EQ(by_topic["/velodyne_points"].imported, 1u);
  EXPECT_EQ(by_topic["/camera"].imported, 1u);  // a camera is named by its namespace
  EXPECT_EQ(report->skipped_topics.at("/tf"), "tf2_msgs/TFMessage");

  auto missing = SensorLogWriter::open(log);
  RosbagImportConfig config;
  config.topic_map = {{"/nope", "/x"}};
  EXPECT_THAT(import_rosbag(bag, **missing, config).error().message, HasSubstr("the bag has no topic '/nope'"));
  config.topic_map = {{"/tf", "/tf"}};
  EXPECT_THAT(import_rosbag(bag, **missing, config).error().message, HasSubstr("tf2_msgs/TFMessage, which cannot be imported"));
  ASSERT_TRUE((*missing)->close().ok());
  std::filesystem::remove(bag);
  std::filesystem::remove(log);
}

}  // namespace
}  // namespace hanzo::fusion::io::ros1
