// CDR decoding details the Foxglove-written bags (rosbag2_conformance_test.cpp) do not reach:
// big-endian and XCDR2 encapsulations, bad headers, simulated-time point clouds, CameraInfo and
// /tf_static edge cases, image_transport's compressedDepth.

#include <cstring>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "hanzo/fusion/io/ros_conversion.hpp"

namespace hanzo::fusion::io::ros {
namespace {

using ::testing::HasSubstr;
constexpr Serialization kCdr = Serialization::kCdr;

// Writes CDR as ROS 2 does: the encapsulation header, then primitives aligned to their size
// (capped at max_alignment) from the end of that header.
class CdrWriter {
 public:
  explicit CdrWriter(bool big_endian = false, std::size_t max_alignment = 8) : big_endian_(big_endian), max_alignment_(max_alignment) {
    const char kind = static_cast<char>(max_alignment == 8 ? (big_endian ? 0x00 : 0x01) : (big_endian ? 0x06 : 0x07));
    out_ = std::string{'\0', kind, '\0', '\0'};
  }
  template <typename T>
  CdrWriter& put(T value) {
    const std::size_t alignment = std::min(sizeof(T), max_alignment_);
    while ((out_.size() - 4) % alignment != 0) out_.push_back('\0');
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));
    for (std::size_t i = 0; i < sizeof(T); ++i) out_.push_back(bytes[big_endian_ ? sizeof(T) - 1 - i : i]);
    return *this;
  }
  CdrWriter& string(const std::string& text) {
    put<uint32_t>(static_cast<uint32_t>(text.size() + 1));
    out_ += text;
    out_.push_back('\0');
    return *this;
  }
  CdrWriter& bytes(const std::string& data) {
    put<uint32_t>(static_cast<uint32_t>(data.size()));
    out_ += data;
    return *this;
  }
  CdrWriter& header(int32_t sec, uint32_t nanosec, const std::string& frame) { return put(sec).put(nanosec).string(frame); }
  CdrWriter& doubles(std::initializer_list<double> values) {
    for (double v : values) put(v);
    return *this;
  }
  const std::string& data() const { return out_; }

 private:
  bool big_endian_;
  std::size_t max_alignment_;
  std::string out_;
};

std::string imu(bool big_endian, std::size_t max_alignment) {
  CdrWriter w(big_endian, max_alignment);
  w.header(100, 250, "imu_link").doubles({0, 0, 0, 1});
  for (int i = 0; i < 9; ++i) w.put(i % 4 == 0 ? 0.01 : 0.0);
  w.doubles({0.1, -0.2, 0.3});
  for (int i = 0; i < 9; ++i) w.put(0.0);
  w.doubles({1.0, 2.0, 9.81});
  for (int i = 0; i < 9; ++i) w.put(0.0);
  return w.data();
}

TEST(CdrDecoding, LittleBigEndianAndXcdr2GiveTheSameImu) {
  for (bool big_endian : {false, true}) {
    for (std::size_t alignment : {8, 4}) {
      SCOPED_TRACE(::testing::Message() << "big endian " << big_endian << ", alignment " << alignment);
      auto m = imu_from_ros(imu(big_endian, alignment), kCdr);
      ASSERT_TRUE(m.ok()) << m.error().message;
      EXPECT_EQ(m->timestamp.nanoseconds(), 100'000'000'250);
      EXPECT_EQ(m->frame_id, "imu_link");  // the NUL terminator is not part of the name
      EXPECT_EQ(m->angular_velocity, Eigen::Vector3d(0.1, -0.2, 0.3));
      EXPECT_EQ(m->linear_acceleration, Eigen::Vector3d(1.0, 2.0, 9.81));
      ASSERT_TRUE(m->orientation_covariance.has_value());
      EXPECT_EQ((*m->orientation_covariance)(2, 2), 0.01);
    }
  }
}

// sensor_msgs/msg/Range: the uint8 radiation type, then float32s aligned to 4 after it.
TEST(CdrDecoding, RangeFloatsAreAlignedAfterTheRadiationType) {
  for (bool big_endian : {false, true}) {
    CdrWriter w(big_endian);
    w.header(100, 250, "sonar").put<uint8_t>(1).put(0.25F).put(0.03125F).put(4.0F).put(1.5F);
    auto range = range_from_ros(w.data(), kCdr);
    ASSERT_TRUE(range.ok()) << range.error().message;
    EXPECT_EQ(range->frame_id, "sonar");
    EXPECT_EQ(range->radiation, msgs::RangeRadiation::kInfrared);
    EXPECT_EQ(range->field_of_view, 0.25F);
    EXPECT_EQ(range->min_range, 0.03125F);
    EXPECT_EQ(range->max_range, 4.0F);
    EXPECT_EQ(range->range, 1.5F);
  }
}

TEST(CdrDecoding, BadEncapsulationAndTruncationAreErrors) {
  std::string bad = imu(false, 8);
  bad[1] = 0x02;  // PL_CDR: a parameter list, not a fixed layout
  EXPECT_THAT(imu_from_ros(bad, kCdr).error().message, HasSubstr("sensor_msgs/Imu: truncated or malformed"));
  EXPECT_FALSE(imu_from_ros("", kCdr).ok());
  const std::string whole = imu(false, 8);
  for (std::size_t size : {3ul, 4ul, 20ul, whole.size() - 1}) {
    EXPECT_FALSE(imu_from_ros(whole.substr(0, size), kCdr).ok()) << size;
  }
  // A string length running past the end.
  std::string long_frame = whole;
  long_frame[15] = '\x7f';  // the high byte of frame_id's length
  EXPECT_FALSE(imu_from_ros(long_frame, kCdr).ok());
}

// vision_msgs/Detection2DArray: two detections, the first with two hypotheses.
std::string detection_array(bool big_endian, std::size_t max_alignment) {
  CdrWriter w(big_endian, max_alignment);
  w.header(100, 5, "camera").put<uint32_t>(2);
  const auto hypothesis = [&w](const std::string& class_id, double score) {
    w.string(class_id).put(score);
    for (int i = 0; i < 7 + 36; ++i) w.put(i == 6 ? 1.0 : 0.0);  // pose (unit quaternion) and covariance
  };
  w.header(100, 5, "camera").put<uint32_t>(2);
  hypothesis("car", 0.25);
  hypothesis("person", 0.5);
  w.doubles({12.5, 20.0, 0.0, 8.0, 16.0}).string("7");
  w.header(100, 5, "camera").put<uint32_t>(1);
  hypothesis("3", 0.9);
  w.doubles({40.0, 10.0, 0.5, 4.0, 2.0}).string("");
  return w.data();
}

TEST(CdrDecoding, Detection2DArrayKeepsTheBestHypothesisAndTheBox) {
  for (const bool big_endian : {false, true}) {
    for (const std::size_t alignment : {8ul, 4ul}) {
      auto array = detections_from_ros(detection_array(big_endian, alignment), kCdr);
      ASSERT_TRUE(array.ok()) << array.error().message;
      EXPECT_EQ(array->stamp.nanoseconds(), 100'000'000'005);
      EXPECT_EQ(array->frame_id, "camera");
      ASSERT_EQ(array->detections.size(), 2u);
      EXPECT_EQ(array->detections[0].class_id, "person");
      EXPECT_EQ(array->detections[0].score, 0.5);
      EXPECT_EQ(array->detections[0].center_x, 12.5);
      EXPECT_EQ(array->detections[0].size_y, 16.0);
      EXPECT_EQ(array->detections[0].id, "7");
      EXPECT_EQ(array->detections[1].class_id, "3");
      EXPECT_EQ(array->detections[1].theta, 0.5);
      EXPECT_EQ(array->detections[1].id, "");
    }
  }
  const std::string whole = detection_array(false, 8);
  for (std::size_t size : {4ul, 30ul, 200ul, whole.size() - 1}) EXPECT_FALSE(detections_from_ros(whole.substr(0, size), kCdr).ok()) << size;
  // A count of detections that the data cannot hold is refused before anything is allocated.
  CdrWriter huge;
  huge.header(1, 0, "camera").put<uint32_t>(0xFFFFFFF0U);
  EXPECT_THAT(detections_from_ros(huge.data(), kCdr).error().message, HasSubstr("vision_msgs/Detection2DArray: truncated or malformed"));
  CdrWriter no_class;
  no_class.header(1, 0, "camera").put<uint32_t>(1).header(1, 0, "camera").put<uint32_t>(0).doubles({1, 1, 0, 1, 1}).string("");
  EXPECT_THAT(detections_from_ros(no_class.data(), kCdr).error().message, HasSubstr("detections[0] has no class hypothesis"));
  EXPECT_THAT(detections_from_ros(whole, Serialization::kRos1).error().message, HasSubstr("only the ROS 2 layout"));
}

TEST(CdrDecoding, LabelInfoNamesClassIds) {
  CdrWriter w;
  w.header(1, 0, "camera").put<uint32_t>(2).put<uint16_t>(0).string("person").put<uint16_t>(7).string("wall").put(0.5F);
  auto table = label_info_from_ros(w.data(), kCdr);
  ASSERT_TRUE(table.ok()) << table.error().message;
  EXPECT_EQ(table->class_names, (std::map<uint16_t, std::string>{{0, "person"}, {7, "wall"}}));
  EXPECT_EQ(table->threshold, 0.5F);
  CdrWriter empty_name;
  empty_name.header(1, 0, "camera").put<uint32_t>(1).put<uint16_t>(3).string("").put(0.5F);
  EXPECT_THAT(label_info_from_ros(empty_name.data(), kCdr).error().message, HasSubstr("class id 3 has an empty name"));
  EXPECT_FALSE(label_info_from_ros(w.data().substr(0, w.data().size() - 2), kCdr).ok());
}

std::string cloud_with_time(int32_t stamp_sec, uint8_t time_datatype, double first_time) {
  CdrWriter w;
  w.header(stamp_sec, 0, "lidar").put<uint32_t>(1).put<uint32_t>(2).put<uint32_t>(4);
  const std::string names[] = {"x", "y", "z", "time"};
  for (uint32_t f = 0; f < 4; ++f) {
    w.string(names[f]).put<uint32_t>(f * 4).put<uint8_t>(f < 3 ? 7 : time_datatype).put<uint32_t>(1);
  }
  const uint32_t point_step = time_datatype == 8 ? 20 : 16;
  w.put<uint8_t>(0).put<uint32_t>(point_step).put<uint32_t>(2 * point_step);
  std::string points(2 * point_step, '\0');
  for (int k = 0; k < 2; ++k) {
    const float xyz[3] = {1.0f + static_cast<float>(k), 2.0f, 3.0f};
    std::memcpy(points.data() + k * point_step, xyz, 12);
    const double t = first_time + k * 0.001;
    if (time_datatype == 8) std::memcpy(points.data() + k * point_step + 12, &t, 8);
    else if (time_datatype == 7) { const float f = static_cast<float>(t); std::memcpy(points.data() + k * point_step + 12, &f, 4); }
    else { const uint32_t n = static_cast<uint32_t>(t); std::memcpy(points.data() + k * point_step + 12, &n, 4); }
  }
  w.bytes(points).put<uint8_t>(1);
  return w.data();
}

TEST(CdrDecoding, PointTimesRelativeOrAbsoluteBySize) {
  // Simulated time (a stamp of 5 s): float times are offsets even where they look like seconds.
  auto simulated = point_cloud_from_ros(cloud_with_time(5, 7, 0.0625), kCdr);  // exact in float32
  ASSERT_TRUE(simulated.ok()) << simulated.error().message;
  EXPECT_EQ(simulated->point_timestamps[0].nanoseconds(), 5'062'500'000);
  // Wall-clock stamps: float64 absolute seconds (Hesai) and absolute nanoseconds (Livox).
  auto seconds = point_cloud_from_ros(cloud_with_time(1'700'000'000, 8, 1'699'999'999.95), kCdr);
  ASSERT_TRUE(seconds.ok());
  EXPECT_EQ(seconds->point_timestamps[0].nanoseconds(), 1'699'999'999'950'000'000);
  EXPECT_EQ(seconds->point_timestamps[1].nanoseconds(), 1'699'999'999'951'000'000);
  auto nanoseconds = point_cloud_from_ros(cloud_with_time(1'700'000'000, 8, 1.7e18 + 2048), kCdr);
  ASSERT_TRUE(nanoseconds.ok());
  EXPECT_EQ(nanoseconds->point_timestamps[0].nanoseconds(), 1'700'000'000'000'002'048);
  // uint32 nanoseconds after the stamp (Ouster).
  auto offsets = point_cloud_from_ros(cloud_with_time(1'700'000'000, 6, 781'250), kCdr);
  ASSERT_TRUE(offsets.ok());
  EXPECT_EQ(offsets->point_timestamps[0].nanoseconds(), 1'700'000'000'000'781'250);
  EXPECT_FALSE(point_cloud_from_ros(cloud_with_time(1'700'000'000, 8, std::nan("")), kCdr).ok());
  // Times beyond int64 nanoseconds are refused (found by UBSan: the conversion overflowed).
  auto huge = point_cloud_from_ros(cloud_with_time(1'700'000'000, 8, -9.3e18), kCdr);
  ASSERT_FALSE(huge.ok());
  EXPECT_NE(huge.error().message.find("out of range"), std::string::npos) << huge.error().message;
}

std::string camera_info(const std::string& model, std::vector<double> d, double fx) {
  CdrWriter w;
  w.header(1, 0, "camera").put<uint32_t>(480).put<uint32_t>(640).string(model).put<uint32_t>(static_cast<uint32_t>(d.size()));
  for (double v : d) w.put(v);
  w.doubles({fx, 0, 320, 0, fx, 240, 0, 0, 1});
  return w.data();
}

TEST(CdrDecoding, CameraInfoModels) {
  auto plumb_bob = camera_info_from_ros(camera_info("plumb_bob", {0.1, -0.2, 0.001, 0.002, 0.05}, 500), kCdr);
  ASSERT_TRUE(plumb_bob.ok()) << plumb_bob.error().message;
  EXPECT_EQ(plumb_bob->camera.distortion.type, msgs::DistortionType::kRadtan);
  EXPECT_EQ(plumb_bob->camera.intrinsics.width, 640u);
  EXPECT_EQ(plumb_bob->camera.intrinsics.cy, 240.0);
  auto rational = camera_info_from_ros(camera_info("rational_polynomial", {0.1, -0.2, 0.001, 0.002, 0.05, 0, 0, 0}, 500), kCdr);
  ASSERT_TRUE(rational.ok());
  EXPECT_EQ(rational->camera.distortion.coefficients.size(), 5u);
  EXPECT_THAT(camera_info_from_ros(camera_info("rational_polynomial", {0.1, -0.2, 0, 0, 0, 0.3, 0, 0}, 500), kCdr).error().message,
              HasSubstr("k4..k6 are not zero"));
  auto fisheye = camera_info_from_ros(camera_info("equidistant", {0.01, 0.02, 0.03, 0.04}, 500), kCdr);
  ASSERT_TRUE(fisheye.ok());
  EXPECT_EQ(fisheye->camera.distortion.type, msgs::DistortionType::kEquidistant);
  auto ideal = camera_info_from_ros(camera_info("", {}, 500), kCdr);
  ASSERT_TRUE(ideal.ok());
  EXPECT_EQ(ideal->camera.distortion.type, msgs::DistortionType::kNone);
  EXPECT_THAT(camera_info_from_ros(camera_info("plumb_bob", {}, 0), kCdr).error().message, HasSubstr("uncalibrated"));
  EXPECT_THAT(camera_info_from_ros(camera_info("unified", {0.5}, 500), kCdr).error().message, HasSubstr("'unified'"));
}

TEST(CdrDecoding, TransformsNeedUnitQuaternions) {
  auto message = [](double qw) {
    CdrWriter w;
    w.put<uint32_t>(1).header(0, 0, "base_link").string("lidar").doubles({1, 2, 3, 0, 0, 0, qw});
    return w.data();
  };
  auto good = transforms_from_ros(message(1.0), kCdr);
  ASSERT_TRUE(good.ok()) << good.error().message;
  ASSERT_EQ(good->size(), 1u);
  EXPECT_EQ((*good)[0].parent_frame, "base_link");
  EXPECT_EQ((*good)[0].child_frame, "lidar");
  EXPECT_EQ((*good)[0].T_parent_child.translation(), Eigen::Vector3d(1, 2, 3));
  EXPECT_THAT(transforms_from_ros(message(0.5), kCdr).error().message, HasSubstr("base_link -> lidar has no unit rotation"));
  CdrWriter huge;
  huge.put<uint32_t>(100000);  // more transforms than bytes
  EXPECT_THAT(transforms_from_ros(huge.data(), kCdr).error().message, HasSubstr("truncated"));
}

TEST(CdrDecoding, CompressedDepthAndUndecodableImages) {
  cv::Mat depth(4, 6, CV_16UC1);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 6; ++c) depth.at<uint16_t>(r, c) = static_cast<uint16_t>(1000 * r + c);
  }
  std::vector<uchar> png;
  ASSERT_TRUE(cv::imencode(".png", depth, png));
  const std::string file = std::string(12, '\0') + std::string(png.begin(), png.end());
  CdrWriter w;
  w.header(2, 0, "depth").string("16UC1; compressedDepth png").bytes(file);
  auto image = compressed_image_from_ros(w.data(), kCdr);
  ASSERT_TRUE(image.ok()) << image.error().message;
  EXPECT_EQ(image->encoding, msgs::ImageEncoding::kDepth16);
  ASSERT_EQ(image->data.size(), 4u * 6u * 2u);
  uint16_t last;
  std::memcpy(&last, image->data.data() + image->data.size() - 2, 2);
  EXPECT_EQ(last, 3005);

  CdrWriter inverse_depth;
  inverse_depth.header(2, 0, "depth").string("32FC1; compressedDepth png").bytes(file);
  EXPECT_THAT(compressed_image_from_ros(inverse_depth.data(), kCdr).error().message, HasSubstr("16UC1 only"));
  CdrWriter garbage;
  garbage.header(2, 0, "camera").string("jpeg").bytes("not a jpeg file");
  EXPECT_THAT(compressed_image_from_ros(garbage.data(), kCdr).error().message, HasSubstr("do not decode as JPEG or PNG"));
}

// Sizes a message declares are checked before anything of that size is allocated (inputs the
// fuzz target fuzz/ros_messages_fuzzer.cpp found, as std::bad_alloc or minutes-long loops).
TEST(CdrDecoding, DeclaredSizesAreCheckedBeforeAllocating) {
  CdrWriter fields;
  fields.header(1, 0, "lidar").put<uint32_t>(1).put<uint32_t>(2).put<uint32_t>(0xFFFFFFF0u);  // field count
  EXPECT_FALSE(point_cloud_from_ros(fields.data(), kCdr).ok());

  CdrWriter rows;  // 4e9 empty rows of a cloud with no points per row
  rows.header(1, 0, "lidar").put<uint32_t>(4000000000u).put<uint32_t>(0).put<uint32_t>(3);
  for (uint32_t f = 0; f < 3; ++f) rows.string(std::string(1, static_cast<char>('x' + f))).put<uint32_t>(f * 4).put<uint8_t>(7).put<uint32_t>(1);
  rows.put<uint8_t>(0).put<uint32_t>(12).put<uint32_t>(0).bytes("").put<uint8_t>(1);
  EXPECT_FALSE(point_cloud_from_ros(rows.data(), kCdr).ok());

  // A field offset near 2^32 (found by libFuzzer): offset + size wrapped into the point step and
  // the reader went 4 GB past the data. Such a field is not used; without x, the cloud is refused.
  CdrWriter wrapped;
  wrapped.header(1, 0, "lidar").put<uint32_t>(1).put<uint32_t>(1).put<uint32_t>(3);
  for (uint32_t f = 0; f < 3; ++f) {
    wrapped.string(std::string(1, static_cast<char>('x' + f))).put<uint32_t>(f == 0 ? 0xFFFFFFFEu : f * 4).put<uint8_t>(7).put<uint32_t>(1);
  }
  wrapped.put<uint8_t>(0).put<uint32_t>(12).put<uint32_t>(12).bytes(std::string(12, '\0')).put<uint8_t>(1);
  EXPECT_THAT(point_cloud_from_ros(wrapped.data(), kCdr).error().message, HasSubstr("no x, y, z fields"));

  CdrWriter empty_image;  // 0 x 4e9 pixels
  empty_image.header(1, 0, "camera").put<uint32_t>(4000000000u).put<uint32_t>(0).string("mono8").put<uint8_t>(0).put<uint32_t>(0).bytes("");
  EXPECT_FALSE(image_from_ros(empty_image.data(), kCdr).ok());

  // A PNG whose header declares 100000 x 100000 pixels: refused before OpenCV would allocate them.
  cv::Mat tiny(2, 2, CV_8UC1, cv::Scalar(7));
  std::vector<uchar> png;
  ASSERT_TRUE(cv::imencode(".png", tiny, png));
  for (int i : {16, 20}) {  // IHDR width and height, big-endian
    png[static_cast<std::size_t>(i)] = 0;
    png[static_cast<std::size_t>(i) + 1] = 0x01;
    png[static_cast<std::size_t>(i) + 2] = 0x86;
    png[static_cast<std::size_t>(i) + 3] = 0xA0;
  }
  CdrWriter huge;
  huge.header(1, 0, "camera").string("png").bytes(std::string(png.begin(), png.end()));
  EXPECT_THAT(compressed_image_from_ros(huge.data(), kCdr).error().message, HasSubstr("declares 100000 x 100000 pixels"));
}

TEST(CdrDecoding, TypeNames) {
  EXPECT_EQ(normalized_type("sensor_msgs/msg/Imu"), "sensor_msgs/Imu");
  EXPECT_EQ(normalized_type("sensor_msgs/Imu"), "sensor_msgs/Imu");
}

}  // namespace
}  // namespace hanzo::fusion::io::ros
