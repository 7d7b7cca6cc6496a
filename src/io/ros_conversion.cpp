#include "hanzo/fusion/io/ros_conversion.hpp"
#include "hanzo/fusion/io/image_file_check.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <optional>
#include <utility>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/msgs/validate.hpp"
#include "ros_wire_reader.hpp"

namespace hanzo::fusion::io::ros {
namespace {

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

// How a PointCloud2's per-point time field counts, told from its type and its first value.
enum class PointTimeUnit { kOffsetSeconds, kOffsetNanoseconds, kAbsoluteSeconds, kAbsoluteNanoseconds };

template <typename Field>
PointTimeUnit point_time_unit(const Field& field, double first_value, Timestamp stamp) {
  const bool floating = field.datatype == 7 || field.datatype == 8;
  if (!floating) return PointTimeUnit::kOffsetNanoseconds;
  // Absolute times lie within a day of the stamp; a stamp within a day of zero (simulated
  // time) leaves offsets and absolute times apart only by convention: offsets then.
  constexpr double kDay = 86400.0;
  const double stamp_seconds = stamp.seconds();
  if (stamp_seconds > kDay && std::abs(first_value - stamp_seconds) < kDay) return PointTimeUnit::kAbsoluteSeconds;
  if (stamp_seconds > kDay && std::abs(first_value * 1e-9 - stamp_seconds) < kDay) return PointTimeUnit::kAbsoluteNanoseconds;
  return PointTimeUnit::kOffsetSeconds;
}

}  // namespace

std::string normalized_type(std::string_view type) {
  std::string name(type);
  if (const auto at = name.find("/msg/"); at != std::string::npos) name.erase(at, 4);
  return name;
}

Result<msgs::ImuMessage> imu_from_ros(std::string_view data, Serialization serialization) {
  WireReader r(data, serialization);
  msgs::ImuMessage imu;
  std::tie(imu.timestamp, imu.frame_id) = r.header();
  const double qx = r.f64(), qy = r.f64(), qz = r.f64(), qw = r.f64();
  const auto orientation_covariance = r.f64_array<9>();
  imu.angular_velocity = r.vector3();
  const auto gyroscope_covariance = r.f64_array<9>();
  imu.linear_acceleration = r.vector3();
  const auto acceleration_covariance = r.f64_array<9>();
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

Result<msgs::GnssMessage> gnss_from_ros(std::string_view data, Serialization serialization) {
  WireReader r(data, serialization);
  msgs::GnssMessage gnss;
  gnss.timestamp = r.header().first;
  const int8_t fix_status = r.i8();  // NavSatStatus.status
  r.u16();                           // NavSatStatus.service
  gnss.latitude = r.f64();
  gnss.longitude = r.f64();
  gnss.altitude = r.f64();
  const auto covariance = r.f64_array<9>();
  const uint8_t covariance_type = r.u8();
  if (!r.ok()) return truncated("sensor_msgs/NavSatFix");
  gnss.fix_type = fix_status < 0    ? msgs::GnssFixType::kNoFix
                  : fix_status == 2 ? msgs::GnssFixType::kRtkFixed
                                    : msgs::GnssFixType::kFix3d;
  if (covariance_type != 0) gnss.position_covariance = covariance_or_none(covariance);
  return gnss;
}

Result<msgs::RangeMessage> range_from_ros(std::string_view data, Serialization serialization) {
  WireReader r(data, serialization);
  msgs::RangeMessage range;
  std::tie(range.timestamp, range.frame_id) = r.header();
  range.radiation = static_cast<msgs::RangeRadiation>(r.u8());
  range.field_of_view = r.f32();
  range.min_range = r.f32();
  range.max_range = r.f32();
  range.range = r.f32();
  if (!r.ok()) return truncated("sensor_msgs/Range");
  return range;
}

Result<msgs::PointCloudMessage> point_cloud_from_ros(std::string_view data, Serialization serialization) {
  WireReader r(data, serialization);
  msgs::PointCloudMessage cloud;
  std::tie(cloud.timestamp, cloud.frame_id) = r.header();
  const uint32_t height = r.u32();
  const uint32_t width = r.u32();
  struct Field {
    std::string name;
    uint32_t offset;
    uint8_t datatype;
  };
  const uint32_t field_count = r.u32();
  if (!r.ok() || field_count > 1024) return truncated("sensor_msgs/PointCloud2");  // checked before anything is allocated
  std::vector<Field> fields(field_count);
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
        // In 64 bits: an offset near 2^32 must not wrap around into range.
        if (f.name == name && f.datatype >= 1 && f.datatype <= 8 && uint64_t{f.offset} + kSize[f.datatype] <= point_step) return &f;
      }
    }
    return nullptr;
  };
  const Field* x = find({"x"});
  const Field* y = find({"y"});
  const Field* z = find({"z"});
  if (!x || !y || !z) return Error("sensor_msgs/PointCloud2: no x, y, z fields");
  const Field* intensity = find({"intensity", "i"});
  const Field* ring = find({"ring", "line", "channel"});
  const Field* time = find({"time", "t", "timestamp", "time_stamp", "offset_time"});
  if (static_cast<uint64_t>(row_step) * height > bytes.size() || static_cast<uint64_t>(point_step) * width > row_step ||
      (row_step == 0 && height > 1)) {
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
  auto point_at = [&](uint32_t row, uint32_t column) {
    return bytes.data() + static_cast<std::size_t>(row) * row_step + static_cast<std::size_t>(column) * point_step;
  };
  const PointTimeUnit time_unit =
      time && width > 0 && height > 0 ? point_time_unit(*time, value(*time, point_at(0, 0)), cloud.timestamp) : PointTimeUnit::kOffsetSeconds;
  for (uint32_t row = 0; row < height; ++row) {
    for (uint32_t column = 0; column < width; ++column) {
      const char* point = point_at(row, column);
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
        if (!std::isfinite(t)) return Error("sensor_msgs/PointCloud2: a non-finite point time");
        // Offsets beyond a day and absolute times beyond int64 nanoseconds are not point times.
        const bool offset = time_unit == PointTimeUnit::kOffsetSeconds || time_unit == PointTimeUnit::kOffsetNanoseconds;
        const bool nanoseconds = time_unit == PointTimeUnit::kOffsetNanoseconds || time_unit == PointTimeUnit::kAbsoluteNanoseconds;
        const double seconds = nanoseconds ? t * 1e-9 : t;
        if (std::abs(seconds) > (offset ? 86400.0 : 9.0e9)) return Error(fmt::format("sensor_msgs/PointCloud2: point time {} is out of range", t));
        switch (time_unit) {
          case PointTimeUnit::kOffsetSeconds:
            cloud.point_timestamps.push_back(cloud.timestamp + Duration::from_nanoseconds(std::llround(t * 1e9)));
            break;
          case PointTimeUnit::kOffsetNanoseconds:
            cloud.point_timestamps.push_back(cloud.timestamp + Duration::from_nanoseconds(static_cast<int64_t>(t)));
            break;
          case PointTimeUnit::kAbsoluteSeconds:
            cloud.point_timestamps.push_back(Timestamp::from_nanoseconds(std::llround(t * 1e6) * 1000));  // microseconds: float noise
            break;
          case PointTimeUnit::kAbsoluteNanoseconds:
            cloud.point_timestamps.push_back(Timestamp::from_nanoseconds(std::llround(t)));
            break;
        }
      }
    }
  }
  if (cloud.points.empty()) return Error("sensor_msgs/PointCloud2: no finite points");
  return cloud;
}

Result<msgs::ImageMessage> image_from_ros(std::string_view data, Serialization serialization) {
  WireReader r(data, serialization);
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
  if (image.width == 0 || image.height == 0 || step < row_bytes || static_cast<uint64_t>(step) * image.height > pixels.size()) {
    return Error(fmt::format("sensor_msgs/Image: {}x{} {} with step {} does not fit in {} bytes", image.width, image.height,
                             encoding, step, pixels.size()));
  }
  image.data.resize(row_bytes * image.height);
  for (uint32_t row = 0; row < image.height; ++row) {
    std::memcpy(image.data.data() + row * row_bytes, pixels.data() + static_cast<std::size_t>(row) * step, row_bytes);
  }
  return image;
}

Result<OdometryTwist> odometry_twist_from_ros(std::string_view data, Serialization serialization) {
  WireReader r(data, serialization);
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

Result<OdometryTwist> twist_stamped_from_ros(std::string_view data, Serialization serialization) {
  WireReader r(data, serialization);
  OdometryTwist twist;
  std::tie(twist.stamp, twist.child_frame_id) = r.header();
  const Eigen::Vector3d linear = r.vector3();
  const Eigen::Vector3d angular = r.vector3();
  if (!r.ok()) return truncated("geometry_msgs/TwistStamped");
  twist.forward_speed = linear.x();
  twist.yaw_rate = angular.z();
  if (!std::isfinite(twist.forward_speed) || !std::isfinite(twist.yaw_rate)) {
    return Error("geometry_msgs/TwistStamped: non-finite twist");
  }
  return twist;
}

namespace {

// Width and height a PNG or JPEG file declares (none for anything else, or a header cut short),
// read before decoding so that a file declaring a huge image is refused without allocating it.
std::optional<std::pair<uint32_t, uint32_t>> declared_image_size(std::string_view file) {
  const auto byte = [&](std::size_t i) { return static_cast<uint32_t>(static_cast<unsigned char>(file[i])); };
  if (file.size() >= 24 && file.substr(1, 3) == "PNG") {  // IHDR: width, height big-endian at 16
    return std::pair{(byte(16) << 24) | (byte(17) << 16) | (byte(18) << 8) | byte(19), (byte(20) << 24) | (byte(21) << 16) | (byte(22) << 8) | byte(23)};
  }
  if (file.size() >= 4 && byte(0) == 0xFF && byte(1) == 0xD8) {  // JPEG: the first start-of-frame marker
    for (std::size_t i = 2; i + 9 <= file.size();) {
      if (byte(i) != 0xFF) return std::nullopt;
      const uint32_t marker = byte(i + 1);
      const bool start_of_frame = marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
      if (start_of_frame) return std::pair{(byte(i + 7) << 8) | byte(i + 8), (byte(i + 5) << 8) | byte(i + 6)};
      i += 2 + ((byte(i + 2) << 8) | byte(i + 3));
    }
  }
  return std::nullopt;
}

}  // namespace

Result<msgs::ImageMessage> compressed_image_from_ros(std::string_view data, Serialization serialization) {
  WireReader r(data, serialization);
  msgs::ImageMessage image;
  std::tie(image.timestamp, image.frame_id) = r.header();
  const std::string format = r.string();
  std::string_view file = r.bytes();
  if (!r.ok()) return truncated("sensor_msgs/CompressedImage");
  // image_transport's compressedDepth: "16UC1; compressedDepth png", a 12-byte configuration
  // header (format, two depth quantization parameters) before the PNG file.
  const bool compressed_depth = format.find("compressedDepth") != std::string::npos;
  if (compressed_depth) {
    if (format.rfind("16UC1", 0) != 0) {
      return Error(fmt::format("sensor_msgs/CompressedImage: '{}' is not supported (compressedDepth of 16UC1 only)", format));
    }
    if (file.size() < 12) return truncated("sensor_msgs/CompressedImage");
    file.remove_prefix(12);
  }
  constexpr uint64_t kMaxPixels = 1ull << 26;  // 67 Mpx: beyond any camera
  if (const auto size = declared_image_size(file); size && static_cast<uint64_t>(size->first) * size->second > kMaxPixels) {
    return Error(fmt::format("sensor_msgs/CompressedImage: the file declares {} x {} pixels, more than {}", size->first, size->second, kMaxPixels));
  }
  if (Status complete = check_image_complete(std::string(file), "sensor_msgs/CompressedImage"); !complete) return complete.error();
  const cv::Mat encoded(1, static_cast<int>(file.size()), CV_8UC1, const_cast<char*>(file.data()));
  cv::Mat decoded = file.empty() ? cv::Mat() : cv::imdecode(encoded, cv::IMREAD_UNCHANGED);
  if (decoded.empty()) {
    return Error(fmt::format("sensor_msgs/CompressedImage: the {} bytes of format '{}' do not decode as JPEG or PNG",
                             file.size(), format));
  }
  if (decoded.channels() == 4) cv::cvtColor(decoded, decoded, cv::COLOR_BGRA2BGR);
  if (decoded.type() == CV_8UC1) image.encoding = msgs::ImageEncoding::kMono8;
  else if (decoded.type() == CV_8UC3) image.encoding = msgs::ImageEncoding::kBgr8;
  else if (decoded.type() == CV_16UC1) image.encoding = msgs::ImageEncoding::kDepth16;
  else return Error(fmt::format("sensor_msgs/CompressedImage: '{}' decodes to an unsupported pixel type", format));
  if (compressed_depth && image.encoding != msgs::ImageEncoding::kDepth16) {
    return Error("sensor_msgs/CompressedImage: compressedDepth did not hold a 16-bit PNG");
  }
  image.width = static_cast<uint32_t>(decoded.cols);
  image.height = static_cast<uint32_t>(decoded.rows);
  const std::size_t row_bytes = static_cast<std::size_t>(image.width) * msgs::bytes_per_pixel(image.encoding);
  image.data.resize(row_bytes * image.height);
  for (int row = 0; row < decoded.rows; ++row) std::memcpy(image.data.data() + row * row_bytes, decoded.ptr(row), row_bytes);
  return image;
}

Result<CameraInfo> camera_info_from_ros(std::string_view data, Serialization serialization) {
  WireReader r(data, serialization);
  CameraInfo info;
  std::tie(info.stamp, info.frame_id) = r.header();
  msgs::CameraIntrinsics& intrinsics = info.camera.intrinsics;
  intrinsics.height = r.u32();
  intrinsics.width = r.u32();
  const std::string model = r.string();
  std::vector<double> d = r.f64_sequence();
  const auto k = r.f64_array<9>();
  if (!r.ok()) return truncated("sensor_msgs/CameraInfo");
  intrinsics.fx = k[0];
  intrinsics.fy = k[4];
  intrinsics.cx = k[2];
  intrinsics.cy = k[5];
  if (!(intrinsics.fx > 0.0 && intrinsics.fy > 0.0 && std::isfinite(intrinsics.fx) && std::isfinite(intrinsics.fy) &&
        std::isfinite(intrinsics.cx) && std::isfinite(intrinsics.cy))) {
    return Error(fmt::format("sensor_msgs/CameraInfo of frame '{}': K has no focal lengths (an uncalibrated camera)", info.frame_id));
  }
  const bool no_distortion = std::all_of(d.begin(), d.end(), [](double v) { return v == 0.0; });
  msgs::DistortionModel& distortion = info.camera.distortion;
  if (no_distortion) {
    distortion.type = msgs::DistortionType::kNone;
  } else if ((model == "plumb_bob" || model == "rational_polynomial") && d.size() >= 4) {
    // rational_polynomial: k1 k2 p1 p2 k3 k4 k5 k6; radtan holds it when k4..k6 are zero.
    if (d.size() > 5 && std::any_of(d.begin() + 5, d.end(), [](double v) { return v != 0.0; })) {
      return Error(fmt::format("sensor_msgs/CameraInfo of frame '{}': {} coefficients k4..k6 are not zero; radtan "
                               "holds k1, k2, p1, p2, k3 only", info.frame_id, model));
    }
    d.resize(std::min<std::size_t>(d.size(), 5));
    distortion = {msgs::DistortionType::kRadtan, d};
  } else if ((model == "equidistant" || model == "fisheye") && d.size() == 4) {
    distortion = {msgs::DistortionType::kEquidistant, d};
  } else {
    return Error(fmt::format("sensor_msgs/CameraInfo of frame '{}': distortion model '{}' with {} coefficients is not "
                             "supported (plumb_bob, rational_polynomial, equidistant)", info.frame_id, model, d.size()));
  }
  return info;
}

Result<std::vector<FrameTransform>> transforms_from_ros(std::string_view data, Serialization serialization) {
  WireReader r(data, serialization);
  const uint32_t count = r.u32();
  if (!r.can_take(static_cast<uint64_t>(count) * 64)) return truncated("tf2_msgs/TFMessage");
  std::vector<FrameTransform> transforms(count);
  for (FrameTransform& transform : transforms) {
    std::tie(transform.stamp, transform.parent_frame) = r.header();
    transform.child_frame = r.string();
    const Eigen::Vector3d translation = r.vector3();
    const Eigen::Vector4d q = r.quaternion_wxyz();
    if (!r.ok()) return truncated("tf2_msgs/TFMessage");
    if (!translation.allFinite() || !q.allFinite() || std::abs(q.norm() - 1.0) > msgs::kUnitQuaternionTolerance) {
      return Error(fmt::format("tf2_msgs/TFMessage: the transform {} -> {} has no unit rotation quaternion",
                               transform.parent_frame, transform.child_frame));
    }
    transform.T_parent_child = SE3(SO3::from_quaternion_normalized(Eigen::Quaterniond(q[0], q[1], q[2], q[3])), translation);
  }
  return transforms;
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

}  // namespace hanzo::fusion::io::ros
