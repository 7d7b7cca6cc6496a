#include "hanzo/fusion/io/ros1_conversion.hpp"

#include <cmath>
#include <cstring>

#include <fmt/format.h>

#include "mcap_format.hpp"

namespace hanzo::fusion::io::ros1 {
namespace {

// Sequential reader of ROS1 serialization.
class RosReader {
 public:
  explicit RosReader(std::string_view data) : r_(data) {}
  bool ok() const { return r_.ok(); }
  uint8_t u8() { return r_.u8(); }
  int8_t i8() { return static_cast<int8_t>(r_.u8()); }
  uint16_t u16() { return r_.u16(); }
  uint32_t u32() { return r_.u32(); }
  double f64() {
    const uint64_t bits = r_.u64();
    double value;
    std::memcpy(&value, &bits, sizeof value);
    return value;
  }
  std::string string() { return std::string(r_.string()); }
  std::string_view bytes() { return r_.string(); }
  Timestamp time() {
    const uint32_t sec = u32();
    const uint32_t nsec = u32();
    return Timestamp::from_nanoseconds(static_cast<int64_t>(sec) * 1'000'000'000 + nsec);
  }
  Eigen::Vector3d vector3() {
    const double x = f64(), y = f64(), z = f64();
    return {x, y, z};
  }
  std::array<double, 9> covariance9() {
    std::array<double, 9> c{};
    for (double& v : c) v = f64();
    return c;
  }
  // std_msgs/Header: seq, stamp, frame_id.
  std::pair<Timestamp, std::string> header() {
    u32();
    const Timestamp stamp = time();
    return {stamp, string()};
  }

 private:
  mcap::format::ByteReader r_;
};

Error truncated(const char* type) { return Error(fmt::format("{}: truncated or malformed message data", type)); }

// ROS: all zeros = unknown, [0] == -1 = not provided.
std::optional<Eigen::Matrix3d> covariance_or_none(const std::array<double, 9>& c) {
  if (c[0] == -1.0) return std::nullopt;
  bool all_zero = true;
  for (double v : c) all_zero = all_zero && v == 0.0;
  if (all_zero) return std::nullopt;
  Eigen::Matrix3d m;
  for (int i = 0; i < 9; ++i) m(i / 3, i % 3) = c[static_cast<std::size_t>(i)];
  return m;
}

}  // namespace

Result<msgs::ImuMessage> imu_from_ros(std::string_view data) {
  RosReader r(data);
  msgs::ImuMessage imu;
  std::tie(imu.timestamp, imu.frame_id) = r.header();
  const double qx = r.f64(), qy = r.f64(), qz = r.f64(), qw = r.f64();
  const auto orientation_covariance = r.covariance9();
  imu.angular_velocity = r.vector3();
  const auto gyroscope_covariance = r.covariance9();
  imu.linear_acceleration = r.vector3();
  const auto acceleration_covariance = r.covariance9();
  if (!r.ok()) return truncated("sensor_msgs/Imu");
  const Eigen::Quaterniond q(qw, qx, qy, qz);
  if (orientation_covariance[0] != -1.0 && q.norm() > 0.5) {
    imu.orientation = q.normalized();
    imu.orientation_covariance = covariance_or_none(orientation_covariance);
  }
  imu.gyroscope_covariance = covariance_or_none(gyroscope_covariance);
  imu.acceleration_covariance = covariance_or_none(acceleration_covariance);
  return imu;
}

Result<msgs::GnssMessage> gnss_from_ros(std::string_view data) {
  RosReader r(data);
  msgs::GnssMessage gnss;
  gnss.timestamp = r.header().first;
  const int8_t fix_status = r.i8();  // NavSatStatus.status
  r.u16();                           // NavSatStatus.service
  gnss.latitude = r.f64();
  gnss.longitude = r.f64();
  gnss.altitude = r.f64();
  const auto covariance = r.covariance9();
  const uint8_t covariance_type = r.u8();
  if (!r.ok()) return truncated("sensor_msgs/NavSatFix");
  gnss.fix_type = fix_status < 0    ? msgs::GnssFixType::kNoFix
                  : fix_status == 2 ? msgs::GnssFixType::kRtkFixed
                                    : msgs::GnssFixType::kFix3d;
  if (covariance_type != 0) gnss.position_covariance = covariance_or_none(covariance);
  return gnss;
}

Result<msgs::PointCloudMessage> point_cloud_from_ros(std::string_view data) {
  RosReader r(data);
  msgs::PointCloudMessage cloud;
  std::tie(cloud.timestamp, cloud.frame_id) = r.header();
  const uint32_t height = r.u32();
  const uint32_t width = r.u32();
  struct Field {
    std::string name;
    uint32_t offset;
    uint8_t datatype;
  };
  std::vector<Field> fields(r.u32());
  if (!r.ok() || fields.size() > 1024) return truncated("sensor_msgs/PointCloud2");
  for (Field& f : fields) {
    f.name = r.string();
    f.offset = r.u32();
    f.datatype = r.u8();
    r.u32();  // count
  }
  const bool big_endian = r.u8() != 0;
  const uint32_t point_step = r.u32();
  const uint32_t row_step = r.u32();
  const std::string_view bytes = r.bytes();
  if (!r.ok()) return truncated("sensor_msgs/PointCloud2");
  if (big_endian) return Error("sensor_msgs/PointCloud2: big-endian point data is not supported");
  // PointField datatypes: 1 INT8 2 UINT8 3 INT16 4 UINT16 5 INT32 6 UINT32 7 FLOAT32 8 FLOAT64.
  static constexpr uint32_t kSize[] = {0, 1, 1, 2, 2, 4, 4, 4, 8};
  auto find = [&](std::initializer_list<const char*> names) -> const Field* {
    for (const char* name : names) {
      for (const Field& f : fields) {
        if (f.name == name && f.datatype >= 1 && f.datatype <= 8 && f.offset + kSize[f.datatype] <= point_step) return &f;
      }
    }
    return nullptr;
  };
  const Field* x = find({"x"});
  const Field* y = find({"y"});
  const Field* z = find({"z"});
  if (!x || !y || !z) return Error("sensor_msgs/PointCloud2: no x, y, z fields");
  const Field* intensity = find({"intensity", "i"});
  const Field* ring = find({"ring"});
  const Field* time = find({"time", "t", "timestamp"});
  if (static_cast<uint64_t>(row_step) * height > bytes.size() || static_cast<uint64_t>(point_step) * width > row_step) {
    return Error(fmt::format("sensor_msgs/PointCloud2: {} x {} points of {} bytes do not fit in {} bytes", height, width,
                             point_step, bytes.size()));
  }
  auto value = [&](const Field& f, const char* point) -> double {
    const char* p = point + f.offset;
    switch (f.datatype) {
      case 1: return static_cast<int8_t>(*p);
      case 2: return static_cast<uint8_t>(*p);
      case 3: { int16_t v; std::memcpy(&v, p, 2); return v; }
      case 4: { uint16_t v; std::memcpy(&v, p, 2); return v; }
      case 5: { int32_t v; std::memcpy(&v, p, 4); return v; }
      case 6: { uint32_t v; std::memcpy(&v, p, 4); return v; }
      case 7: { float v; std::memcpy(&v, p, 4); return v; }
      default: { double v; std::memcpy(&v, p, 8); return v; }
    }
  };
  const bool time_in_seconds = time && (time->datatype == 7 || time->datatype == 8);
  for (uint32_t row = 0; row < height; ++row) {
    for (uint32_t column = 0; column < width; ++column) {
      const char* point = bytes.data() + static_cast<std::size_t>(row) * row_step + static_cast<std::size_t>(column) * point_step;
      const Eigen::Vector3f p(static_cast<float>(value(*x, point)), static_cast<float>(value(*y, point)),
                              static_cast<float>(value(*z, point)));
      if (!p.allFinite()) continue;  // "no return" points of organized clouds
      cloud.points.push_back(p);
      if (intensity) {
        const double i = value(*intensity, point);
        cloud.intensities.push_back(static_cast<float>(std::clamp(i > 1.0 ? i / 255.0 : i, 0.0, 1.0)));
      }
      if (ring) cloud.ring_ids.push_back(static_cast<uint32_t>(value(*ring, point)));
      if (time) {
        const double t = value(*time, point);
        const int64_t offset_ns = time_in_seconds ? std::llround(t * 1e9) : static_cast<int64_t>(t);
        cloud.point_timestamps.push_back(cloud.timestamp + Duration::from_nanoseconds(offset_ns));
      }
    }
  }
  if (cloud.points.empty()) return Error("sensor_msgs/PointCloud2: no finite points");
  return cloud;
}

Result<msgs::ImageMessage> image_from_ros(std::string_view data) {
  RosReader r(data);
  msgs::ImageMessage image;
  std::tie(image.timestamp, image.frame_id) = r.header();
  image.height = r.u32();
  image.width = r.u32();
  const std::string encoding = r.string();
  r.u8();  // is_bigendian
  const uint32_t step = r.u32();
  const std::string_view pixels = r.bytes();
  if (!r.ok()) return truncated("sensor_msgs/Image");
  if (encoding == "rgb8") image.encoding = msgs::ImageEncoding::kRgb8;
  else if (encoding == "bgr8") image.encoding = msgs::ImageEncoding::kBgr8;
  else if (encoding == "mono8" || encoding == "8UC1") image.encoding = msgs::ImageEncoding::kMono8;
  else if (encoding == "16UC1" || encoding == "mono16") image.encoding = msgs::ImageEncoding::kDepth16;
  else if (encoding == "32FC1") image.encoding = msgs::ImageEncoding::kDepth32f;
  else return Error(fmt::format("sensor_msgs/Image: encoding '{}' is not supported (rgb8, bgr8, mono8, 16UC1, 32FC1)", encoding));
  const std::size_t row_bytes = static_cast<std::size_t>(image.width) * msgs::bytes_per_pixel(image.encoding);
  if (step < row_bytes || static_cast<uint64_t>(step) * image.height > pixels.size()) {
    return Error(fmt::format("sensor_msgs/Image: {}x{} {} with step {} does not fit in {} bytes", image.width, image.height,
                             encoding, step, pixels.size()));
  }
  image.data.resize(row_bytes * image.height);
  for (uint32_t row = 0; row < image.height; ++row) {
    std::memcpy(image.data.data() + row * row_bytes, pixels.data() + static_cast<std::size_t>(row) * step, row_bytes);
  }
  return image;
}

Result<OdometryTwist> odometry_twist_from_ros(std::string_view data) {
  RosReader r(data);
  OdometryTwist twist;
  twist.stamp = r.header().first;
  twist.child_frame_id = r.string();
  for (int i = 0; i < 7 + 36; ++i) r.f64();  // pose + covariance
  twist.forward_speed = r.f64();
  r.f64();
  r.f64();
  r.f64();
  r.f64();
  twist.yaw_rate = r.f64();
  for (int i = 0; i < 36; ++i) r.f64();  // twist covariance
  if (!r.ok()) return truncated("nav_msgs/Odometry");
  if (!std::isfinite(twist.forward_speed) || !std::isfinite(twist.yaw_rate)) {
    return Error("nav_msgs/Odometry: non-finite twist");
  }
  return twist;
}

Result<msgs::WheelOdometryMessage> WheelDistanceIntegrator::add(const OdometryTwist& twist) {
  if (previous_ && twist.stamp <= previous_->stamp) {
    return Error(fmt::format("odometry at {} ns is not after the previous one ({} ns)", twist.stamp.nanoseconds(),
                             previous_->stamp.nanoseconds()));
  }
  if (previous_) {
    const double dt = (twist.stamp - previous_->stamp).seconds();
    const double half = wheel_separation_ / 2.0;
    const double left_before = previous_->forward_speed - previous_->yaw_rate * half;
    const double right_before = previous_->forward_speed + previous_->yaw_rate * half;
    const double left_now = twist.forward_speed - twist.yaw_rate * half;
    const double right_now = twist.forward_speed + twist.yaw_rate * half;
    left_ += 0.5 * (left_before + left_now) * dt;
    right_ += 0.5 * (right_before + right_now) * dt;
  }
  previous_ = twist;
  msgs::WheelOdometryMessage wheel;
  wheel.timestamp = twist.stamp;
  wheel.frame_id = twist.child_frame_id;
  wheel.left_distance = left_;
  wheel.right_distance = right_;
  wheel.wheel_separation = wheel_separation_;
  return wheel;
}

}  // namespace hanzo::fusion::io::ros1
