#include "hanzo/fusion/io/ros2_bag_writer.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <sqlite3.h>

#include "hanzo/fusion/io/mcap.hpp"

namespace hanzo::fusion::io::ros2 {
namespace {

namespace fs = std::filesystem;

// Little-endian CDR (XCDR1): a 4-byte encapsulation header, then primitives aligned to their
// size counted from the end of that header.
class CdrWriter {
 public:
  CdrWriter() : out_{'\0', '\x01', '\0', '\0'} {}
  template <typename T>
  CdrWriter& put(T value) {
    while ((out_.size() - 4) % sizeof(T) != 0) out_.push_back('\0');
    char bytes[sizeof(T)];
    std::memcpy(bytes, &value, sizeof(T));  // the machine is little-endian (x86-64, arm64)
    out_.append(bytes, sizeof(T));
    return *this;
  }
  CdrWriter& string(const std::string& text) {
    put(static_cast<uint32_t>(text.size() + 1));
    out_ += text;
    out_.push_back('\0');
    return *this;
  }
  CdrWriter& bytes(const void* data, std::size_t size) {
    put(static_cast<uint32_t>(size));
    out_.append(static_cast<const char*>(data), size);
    return *this;
  }
  // builtin_interfaces/Time: whole seconds (rounded down) and nanoseconds in [0, 1e9).
  CdrWriter& time(Timestamp stamp) {
    const int64_t ns = stamp.nanoseconds();
    const int64_t sec = ns >= 0 ? ns / 1'000'000'000 : -((-ns + 999'999'999) / 1'000'000'000);
    return put(static_cast<int32_t>(sec)).put(static_cast<uint32_t>(ns - sec * 1'000'000'000));
  }
  CdrWriter& header(Timestamp stamp, const std::string& frame_id) { return time(stamp).string(frame_id); }
  CdrWriter& pose(const msgs::Pose& pose) {
    const Eigen::Quaterniond q = pose.orientation.normalized();
    return put(pose.position.x()).put(pose.position.y()).put(pose.position.z()).put(q.x()).put(q.y()).put(q.z()).put(q.w());
  }
  CdrWriter& vector3(const Eigen::Vector3d& v) { return put(v.x()).put(v.y()).put(v.z()); }
  // float64[9]: the matrix row by row, or `unset` then zeros when there is none.
  CdrWriter& covariance(const std::optional<Eigen::Matrix3d>& matrix, double unset = 0.0) {
    for (int i = 0; i < 9; ++i) put(matrix ? (*matrix)(i / 3, i % 3) : (i == 0 ? unset : 0.0));
    return *this;
  }
  std::string take() { return std::move(out_); }

 private:
  std::string out_;
};

// ROS 2 message definitions (the "ros2msg" schema text: the type's own fields, then each type
// it uses after a separator line and "MSG: pkg/Type").
const std::map<std::string, std::string>& definitions() {
  static const std::map<std::string, std::string> kDefinitions = {
      {"builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"},
      {"std_msgs/Header", "builtin_interfaces/Time stamp\nstring frame_id\n"},
      {"geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"},
      {"geometry_msgs/Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"},
      {"geometry_msgs/Pose", "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"},
      {"geometry_msgs/PoseStamped", "std_msgs/Header header\ngeometry_msgs/Pose pose\n"},
      {"geometry_msgs/PoseWithCovariance", "geometry_msgs/Pose pose\nfloat64[36] covariance\n"},
      {"geometry_msgs/PoseWithCovarianceStamped", "std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n"},
      {"nav_msgs/Path", "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n"},
      {"sensor_msgs/PointField",
       "uint8 INT8=1\nuint8 UINT8=2\nuint8 INT16=3\nuint8 UINT16=4\nuint8 INT32=5\nuint8 UINT32=6\nuint8 FLOAT32=7\n"
       "uint8 FLOAT64=8\nstring name\nuint32 offset\nuint8 datatype\nuint32 count\n"},
      {"sensor_msgs/PointCloud2",
       "std_msgs/Header header\nuint32 height\nuint32 width\nsensor_msgs/PointField[] fields\nbool is_bigendian\n"
       "uint32 point_step\nuint32 row_step\nuint8[] data\nbool is_dense\n"},
      {"nav_msgs/MapMetaData",
       "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\ngeometry_msgs/Pose origin\n"},
      {"nav_msgs/OccupancyGrid", "std_msgs/Header header\nnav_msgs/MapMetaData info\nint8[] data\n"},
      {"geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"},
      {"geometry_msgs/Twist", "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n"},
      {"geometry_msgs/TwistStamped", "std_msgs/Header header\ngeometry_msgs/Twist twist\n"},
      {"sensor_msgs/Imu",
       "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\n"
       "geometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\n"
       "geometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance\n"},
      {"sensor_msgs/NavSatStatus",
       "int8 STATUS_NO_FIX=-1\nint8 STATUS_FIX=0\nint8 STATUS_SBAS_FIX=1\nint8 STATUS_GBAS_FIX=2\nuint16 SERVICE_GPS=1\n"
       "int8 status\nuint16 service\n"},
      {"sensor_msgs/NavSatFix",
       "std_msgs/Header header\nsensor_msgs/NavSatStatus status\nfloat64 latitude\nfloat64 longitude\nfloat64 altitude\n"
       "float64[9] position_covariance\nuint8 COVARIANCE_TYPE_UNKNOWN=0\nuint8 COVARIANCE_TYPE_APPROXIMATED=1\n"
       "uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN=2\nuint8 COVARIANCE_TYPE_KNOWN=3\nuint8 position_covariance_type\n"},
      {"geometry_msgs/Transform", "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n"},
      {"geometry_msgs/TransformStamped", "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n"},
      {"tf2_msgs/TFMessage", "geometry_msgs/TransformStamped[] transforms\n"},
      {"sensor_msgs/RegionOfInterest", "uint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"},
      {"sensor_msgs/CameraInfo",
       "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\nfloat64[9] k\nfloat64[9] r\n"
       "float64[12] p\nuint32 binning_x\nuint32 binning_y\nsensor_msgs/RegionOfInterest roi\n"},
      {"sensor_msgs/Image",
       "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n"},
      {"sensor_msgs/CompressedImage", "std_msgs/Header header\nstring format\nuint8[] data\n"},
      {"vision_msgs/Point2D", "float64 x\nfloat64 y\n"},
      {"vision_msgs/Pose2D", "vision_msgs/Point2D position\nfloat64 theta\n"},
      {"vision_msgs/BoundingBox2D", "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n"},
      {"vision_msgs/ObjectHypothesis", "string class_id\nfloat64 score\n"},
      {"vision_msgs/ObjectHypothesisWithPose", "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"},
      {"vision_msgs/Detection2D",
       "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\nvision_msgs/BoundingBox2D bbox\nstring id\n"},
      {"vision_msgs/Detection2DArray", "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n"},
      {"vision_msgs/VisionClass", "uint16 class_id\nstring class_name\n"},
      {"vision_msgs/LabelInfo", "std_msgs/Header header\nvision_msgs/VisionClass[] class_map\nfloat32 threshold\n"},
  };
  return kDefinitions;
}

// "nav_msgs/msg/Path" -> its schema text, or "" for a type this writer does not know.
std::string schema_text(const std::string& type) {
  std::string name = type;
  if (const auto at = name.find("/msg/"); at != std::string::npos) name.erase(at, 4);
  const auto& all = definitions();
  if (all.count(name) == 0) return "";
  // Depth-first over the field types, each dependency once.
  std::vector<std::string> order;
  std::vector<std::string> pending = {name};
  while (!pending.empty()) {
    const std::string current = pending.back();
    pending.pop_back();
    if (std::find(order.begin(), order.end(), current) != order.end()) continue;
    order.push_back(current);
    std::istringstream lines(all.at(current));
    std::vector<std::string> uses;
    for (std::string line; std::getline(lines, line);) {
      std::string field_type = line.substr(0, line.find(' '));
      if (const auto bracket = field_type.find('['); bracket != std::string::npos) field_type.resize(bracket);
      if (all.count(field_type) != 0) uses.push_back(field_type);
    }
    pending.insert(pending.end(), uses.rbegin(), uses.rend());
  }
  std::string text = all.at(name);
  for (std::size_t i = 1; i < order.size(); ++i) {
    text += std::string(80, '=') + "\nMSG: " + order[i] + "\n" + all.at(order[i]);
  }
  return text;
}

}  // namespace

std::string pose_stamped_cdr(Timestamp stamp, const std::string& frame_id, const msgs::Pose& pose) {
  return CdrWriter().header(stamp, frame_id).pose(pose).take();
}

std::string pose_with_covariance_stamped_cdr(Timestamp stamp, const std::string& frame_id, const msgs::Pose& pose,
                                             const Eigen::Matrix<double, 6, 6>& covariance) {
  CdrWriter w;
  w.header(stamp, frame_id).pose(pose);
  for (int row = 0; row < 6; ++row) {
    for (int column = 0; column < 6; ++column) w.put(covariance(row, column));
  }
  return w.take();
}

std::string path_cdr(Timestamp stamp, const std::string& frame_id, const std::vector<StampedPose>& poses) {
  CdrWriter w;
  w.header(stamp, frame_id).put(static_cast<uint32_t>(poses.size()));
  for (const StampedPose& p : poses) w.header(p.stamp, frame_id).pose(p.pose);
  return w.take();
}

std::string point_cloud_cdr(Timestamp stamp, const std::string& frame_id, const std::vector<Eigen::Vector3f>& points,
                            const std::vector<float>& intensities) {
  const bool with_intensity = !intensities.empty() && intensities.size() == points.size();
  const uint32_t point_step = with_intensity ? 16 : 12;
  CdrWriter w;
  w.header(stamp, frame_id).put<uint32_t>(1).put(static_cast<uint32_t>(points.size()));
  const char* names[] = {"x", "y", "z", "intensity"};
  const uint32_t field_count = with_intensity ? 4 : 3;
  w.put(field_count);
  for (uint32_t f = 0; f < field_count; ++f) w.string(names[f]).put(f * 4).put<uint8_t>(7).put<uint32_t>(1);  // FLOAT32
  std::string data(static_cast<std::size_t>(point_step) * points.size(), '\0');
  for (std::size_t i = 0; i < points.size(); ++i) {
    std::memcpy(data.data() + i * point_step, points[i].data(), 12);
    if (with_intensity) std::memcpy(data.data() + i * point_step + 12, &intensities[i], 4);
  }
  w.put<uint8_t>(0).put(point_step).put(static_cast<uint32_t>(data.size())).bytes(data.data(), data.size());
  const bool dense = std::all_of(points.begin(), points.end(), [](const Eigen::Vector3f& p) { return p.allFinite(); });
  w.put<uint8_t>(dense ? 1 : 0);
  return w.take();
}

Result<std::string> occupancy_grid_cdr(Timestamp stamp, const std::string& frame_id, const msgs::OccupancyGridLayer& layer) {
  if (layer.size_z != 1) return Error(fmt::format("occupancy grid: {} layers in z; nav_msgs/OccupancyGrid is 2D (flatten it)", layer.size_z));
  if (layer.occupancy.size() != static_cast<std::size_t>(layer.size_x) * layer.size_y) {
    return Error(fmt::format("occupancy grid: {} cells for {} x {}", layer.occupancy.size(), layer.size_x, layer.size_y));
  }
  CdrWriter w;
  w.header(stamp, frame_id).time(stamp).put(static_cast<float>(layer.resolution)).put(layer.size_x).put(layer.size_y);
  w.pose(layer.origin);
  std::string cells(layer.occupancy.size(), '\0');
  for (std::size_t i = 0; i < cells.size(); ++i) {
    const float p = layer.occupancy[i];
    const bool unknown = p == 0.5f || !std::isfinite(p);
    cells[i] = static_cast<char>(unknown ? -1 : static_cast<int8_t>(std::lround(std::clamp(p, 0.0f, 1.0f) * 100.0f)));
  }
  w.bytes(cells.data(), cells.size());
  return w.take();
}

Result<LidarLayout> lidar_layout_from_name(const std::string& name) {
  if (name == "plain") return LidarLayout::kPlain;
  if (name == "velodyne") return LidarLayout::kVelodyne;
  if (name == "ouster") return LidarLayout::kOuster;
  if (name == "livox") return LidarLayout::kLivox;
  if (name == "hesai") return LidarLayout::kHesai;
  return Error(fmt::format("unknown LiDAR layout '{}' (plain, velodyne, ouster, livox, hesai)", name));
}

std::string imu_cdr(const msgs::ImuMessage& imu) {
  CdrWriter w;
  w.header(imu.timestamp, imu.frame_id);
  const Eigen::Quaterniond q = imu.orientation.value_or(Eigen::Quaterniond(0, 0, 0, 0));
  w.put(q.x()).put(q.y()).put(q.z()).put(q.w());
  // ROS: orientation_covariance[0] = -1 says "no orientation".
  w.covariance(imu.orientation ? imu.orientation_covariance : std::nullopt, imu.orientation ? 0.0 : -1.0);
  w.vector3(imu.angular_velocity).covariance(imu.gyroscope_covariance);
  w.vector3(imu.linear_acceleration).covariance(imu.acceleration_covariance);
  return w.take();
}

std::string navsatfix_cdr(const msgs::GnssMessage& fix, const std::string& frame_id) {
  const int8_t status = fix.fix_type == msgs::GnssFixType::kNoFix ? -1
                        : (fix.fix_type == msgs::GnssFixType::kRtkFixed || fix.fix_type == msgs::GnssFixType::kRtkFloat) ? 2
                                                                                                                            : 0;
  CdrWriter w;
  w.header(fix.timestamp, frame_id).put(status).put<uint16_t>(1).put(fix.latitude).put(fix.longitude).put(fix.altitude);
  w.covariance(fix.position_covariance).put<uint8_t>(fix.position_covariance ? 3 : 0);
  return w.take();
}

std::string image_cdr(const msgs::ImageMessage& image) {
  static const std::map<msgs::ImageEncoding, std::string> kNames = {{msgs::ImageEncoding::kRgb8, "rgb8"},
                                                                     {msgs::ImageEncoding::kBgr8, "bgr8"},
                                                                     {msgs::ImageEncoding::kMono8, "mono8"},
                                                                     {msgs::ImageEncoding::kDepth16, "16UC1"},
                                                                     {msgs::ImageEncoding::kDepth32f, "32FC1"}};
  CdrWriter w;
  w.header(image.timestamp, image.frame_id).put(image.height).put(image.width).string(kNames.at(image.encoding)).put<uint8_t>(0);
  w.put(static_cast<uint32_t>(image.width * msgs::bytes_per_pixel(image.encoding))).bytes(image.data.data(), image.data.size());
  return w.take();
}

std::string detection_array_cdr(const msgs::DetectionsMessage& detections) {
  CdrWriter w;
  w.header(detections.timestamp, detections.frame_id).put(static_cast<uint32_t>(detections.detections.size()));
  for (const msgs::Detection2D& detection : detections.detections) {
    w.header(detections.timestamp, detections.frame_id).put<uint32_t>(1).string(detection.class_name).put(static_cast<double>(detection.score));
    w.pose(msgs::Pose{});
    for (int i = 0; i < 36; ++i) w.put(0.0);
    w.put(0.5 * (static_cast<double>(detection.x_min) + detection.x_max)).put(0.5 * (static_cast<double>(detection.y_min) + detection.y_max));
    w.put(0.0).put(static_cast<double>(detection.x_max) - detection.x_min).put(static_cast<double>(detection.y_max) - detection.y_min);
    w.string(detection.track_id >= 0 ? std::to_string(detection.track_id) : std::string());
  }
  return w.take();
}

std::string label_image_cdr(const msgs::DetectionsMessage& detections) {
  CdrWriter w;
  w.header(detections.timestamp, detections.frame_id).put(detections.image_height).put(detections.image_width).string("mono8").put<uint8_t>(0);
  w.put(detections.image_width).bytes(detections.segmentation.data(), detections.segmentation.size());
  return w.take();
}

std::string label_info_cdr(Timestamp stamp, const std::string& frame_id, const std::vector<std::string>& classes) {
  CdrWriter w;
  w.header(stamp, frame_id).put(static_cast<uint32_t>(classes.size()));
  for (std::size_t id = 0; id < classes.size(); ++id) w.put(static_cast<uint16_t>(id)).string(classes[id]);
  w.put(0.0F);
  return w.take();
}

std::string compressed_image_cdr(const msgs::ImageMessage& image, const std::string& format, const std::string& file) {
  const std::string encoding(msgs::to_string(image.encoding));
  CdrWriter w;
  w.header(image.timestamp, image.frame_id).string(fmt::format("{}; {} compressed {}", encoding, format, encoding));
  w.bytes(file.data(), file.size());
  return w.take();
}

std::string tf_message_cdr(const std::vector<ros::FrameTransform>& transforms) {
  CdrWriter w;
  w.put(static_cast<uint32_t>(transforms.size()));
  for (const ros::FrameTransform& transform : transforms) {
    w.header(transform.stamp, transform.parent_frame).string(transform.child_frame);
    w.vector3(transform.T_parent_child.translation());
    const Eigen::Quaterniond& q = transform.T_parent_child.rotation().quaternion();
    w.put(q.x()).put(q.y()).put(q.z()).put(q.w());
  }
  return w.take();
}

std::string camera_info_cdr(Timestamp stamp, const std::string& frame_id, const calib::CameraCalibration& camera, uint32_t width,
                            uint32_t height) {
  const msgs::CameraIntrinsics& k = camera.intrinsics;
  const bool equidistant = camera.distortion.type == msgs::DistortionType::kEquidistant;
  std::vector<double> d = camera.distortion.coefficients;
  if (!equidistant) d.resize(5, 0.0);  // plumb_bob: k1 k2 p1 p2 k3
  CdrWriter w;
  w.header(stamp, frame_id).put(height).put(width).string(equidistant ? "equidistant" : "plumb_bob");
  w.put(static_cast<uint32_t>(d.size()));
  for (const double value : d) w.put(value);
  for (const double value : {k.fx, 0.0, k.cx, 0.0, k.fy, k.cy, 0.0, 0.0, 1.0}) w.put(value);
  for (const double value : {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0}) w.put(value);
  for (const double value : {k.fx, 0.0, k.cx, 0.0, 0.0, k.fy, k.cy, 0.0, 0.0, 0.0, 1.0, 0.0}) w.put(value);
  w.put<uint32_t>(0).put<uint32_t>(0);                                                        // binning
  w.put<uint32_t>(0).put<uint32_t>(0).put<uint32_t>(0).put<uint32_t>(0).put<uint8_t>(0);  // roi
  return w.take();
}

std::string twist_stamped_cdr(Timestamp stamp, const std::string& frame_id, double forward_speed, double yaw_rate) {
  return CdrWriter().header(stamp, frame_id).vector3({forward_speed, 0, 0}).vector3({0, 0, yaw_rate}).take();
}

std::string point_cloud_cdr(const msgs::PointCloudMessage& cloud, LidarLayout layout) {
  struct Field {
    const char* name;
    uint32_t offset;
    uint8_t datatype;  // 2 UINT8, 4 UINT16, 6 UINT32, 7 FLOAT32, 8 FLOAT64
  };
  std::vector<Field> fields;
  uint32_t point_step = 0;
  switch (layout) {
    case LidarLayout::kPlain:
    case LidarLayout::kVelodyne:
      fields = {{"x", 0, 7}, {"y", 4, 7}, {"z", 8, 7}, {"intensity", 12, 7}, {"ring", 16, 4}, {"time", 18, 7}};
      point_step = 22;
      break;
    case LidarLayout::kOuster:
      fields = {{"x", 0, 7}, {"y", 4, 7}, {"z", 8, 7}, {"intensity", 16, 7}, {"t", 20, 6}, {"reflectivity", 24, 4}, {"ring", 26, 4}};
      point_step = 32;
      break;
    case LidarLayout::kLivox:
      fields = {{"x", 0, 7}, {"y", 4, 7}, {"z", 8, 7}, {"intensity", 12, 7}, {"tag", 16, 2}, {"line", 17, 2}, {"timestamp", 18, 8}};
      point_step = 26;
      break;
    case LidarLayout::kHesai:
      fields = {{"x", 0, 7}, {"y", 4, 7}, {"z", 8, 7}, {"intensity", 16, 7}, {"timestamp", 24, 8}, {"ring", 32, 4}};
      point_step = 48;
      break;
  }
  std::string data(static_cast<std::size_t>(point_step) * cloud.points.size(), '\0');
  for (std::size_t i = 0; i < cloud.points.size(); ++i) {
    char* point = data.data() + i * point_step;
    const float intensity = cloud.intensities.empty() ? 0.0f : cloud.intensities[i];
    const uint32_t ring = cloud.ring_ids.empty() ? 0 : cloud.ring_ids[i];
    const Timestamp time = cloud.point_timestamps.empty() ? cloud.timestamp : cloud.point_timestamps[i];
    const int64_t offset_ns = (time - cloud.timestamp).nanoseconds();
    for (const Field& f : fields) {
      const std::string_view name = f.name;
      char* at = point + f.offset;
      if (name == "x" || name == "y" || name == "z") {
        std::memcpy(at, &cloud.points[i][name[0] - 'x'], 4);
      } else if (name == "intensity") {
        std::memcpy(at, &intensity, 4);
      } else if (name == "ring" || name == "line") {
        if (f.datatype == 4) { const uint16_t v = static_cast<uint16_t>(ring); std::memcpy(at, &v, 2); }
        else *at = static_cast<char>(ring);
      } else if (name == "time") {
        const float seconds = static_cast<float>(static_cast<double>(offset_ns) * 1e-9);
        std::memcpy(at, &seconds, 4);
      } else if (name == "t") {
        const uint32_t ns = static_cast<uint32_t>(std::max<int64_t>(offset_ns, 0));
        std::memcpy(at, &ns, 4);
      } else if (name == "timestamp") {
        const double value = layout == LidarLayout::kLivox ? static_cast<double>(time.nanoseconds()) : time.seconds();
        std::memcpy(at, &value, 8);
      }
    }
  }
  CdrWriter w;
  w.header(cloud.timestamp, cloud.frame_id).put<uint32_t>(1).put(static_cast<uint32_t>(cloud.points.size()));
  w.put(static_cast<uint32_t>(fields.size()));
  for (const Field& f : fields) w.string(f.name).put(f.offset).put(f.datatype).put<uint32_t>(1);
  w.put<uint8_t>(0).put(point_step).put(static_cast<uint32_t>(data.size())).bytes(data.data(), data.size()).put<uint8_t>(1);
  return w.take();
}

Result<BagStorage> bag_storage_from_name(const std::string& name) {
  if (name == "mcap") return BagStorage::kMcap;
  if (name == "sqlite3") return BagStorage::kSqlite3;
  return Error(fmt::format("unknown ROS 2 bag storage '{}' (mcap or sqlite3)", name));
}

namespace {

// rosbag2's sqlite3 storage as ROS 2 Humble writes it: schema version 3 (topics with their QoS
// profiles, no type hashes), the messages in one table with a timestamp index. One transaction
// for the whole bag (committed by close(); a crash leaves a database without it).
class SqliteBag {
 public:
  static Result<std::unique_ptr<SqliteBag>> open(const std::string& path) {
    auto bag = std::unique_ptr<SqliteBag>(new SqliteBag());
    if (sqlite3_open_v2(path.c_str(), &bag->db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr) != SQLITE_OK) {
      return Error(fmt::format("{}: cannot create the database: {}", path, bag->db_ ? sqlite3_errmsg(bag->db_) : "out of memory"));
    }
    bag->path_ = path;
    HANZO_RETURN_IF_ERROR(bag->execute(
        "PRAGMA journal_mode=MEMORY; PRAGMA synchronous=OFF;"
        "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);"
        "INSERT INTO schema VALUES (3, 'humble');"
        "CREATE TABLE metadata(id INTEGER PRIMARY KEY, metadata_version INTEGER NOT NULL, metadata TEXT NOT NULL);"
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, serialization_format TEXT NOT NULL,"
        " offered_qos_profiles TEXT NOT NULL);"
        "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, data BLOB NOT NULL);"
        "CREATE INDEX timestamp_idx ON messages (timestamp ASC);"
        "BEGIN TRANSACTION;"));
    if (sqlite3_prepare_v2(bag->db_, "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)", -1, &bag->insert_, nullptr) !=
        SQLITE_OK) {
      return bag->failure("prepare");
    }
    return bag;
  }
  ~SqliteBag() {
    sqlite3_finalize(insert_);
    sqlite3_close(db_);
  }

  Result<int64_t> add_topic(const std::string& name, const std::string& type) {
    sqlite3_stmt* statement = nullptr;
    if (sqlite3_prepare_v2(db_, "INSERT INTO topics (name, type, serialization_format, offered_qos_profiles) VALUES (?, ?, 'cdr', '')", -1,
                           &statement, nullptr) != SQLITE_OK) {
      return failure("prepare");
    }
    sqlite3_bind_text(statement, 1, name.c_str(), -1, SQLITE_TRANSIENT);
    sqlite3_bind_text(statement, 2, type.c_str(), -1, SQLITE_TRANSIENT);
    const int stepped = sqlite3_step(statement);
    sqlite3_finalize(statement);
    if (stepped != SQLITE_DONE) return failure("insert a topic");
    return sqlite3_last_insert_rowid(db_);
  }

  Status add_message(int64_t topic_id, int64_t time_ns, const std::string& cdr) {
    sqlite3_reset(insert_);
    sqlite3_bind_int64(insert_, 1, topic_id);
    sqlite3_bind_int64(insert_, 2, time_ns);
    sqlite3_bind_blob64(insert_, 3, cdr.data(), cdr.size(), SQLITE_STATIC);
    if (sqlite3_step(insert_) != SQLITE_DONE) return failure("insert a message");
    return ok_status();
  }

  Status close(const std::string& metadata_yaml) {
    sqlite3_stmt* statement = nullptr;
    if (sqlite3_prepare_v2(db_, "INSERT INTO metadata (metadata_version, metadata) VALUES (5, ?)", -1, &statement, nullptr) != SQLITE_OK) {
      return failure("prepare");
    }
    sqlite3_bind_text(statement, 1, metadata_yaml.c_str(), -1, SQLITE_TRANSIENT);
    const int stepped = sqlite3_step(statement);
    sqlite3_finalize(statement);
    if (stepped != SQLITE_DONE) return failure("write the metadata");
    return execute("COMMIT;");
  }

 private:
  SqliteBag() = default;
  Status execute(const char* sql) {
    char* message = nullptr;
    if (sqlite3_exec(db_, sql, nullptr, nullptr, &message) != SQLITE_OK) {
      const std::string reason = message ? message : "unknown error";
      sqlite3_free(message);
      return Error(fmt::format("{}: {}", path_, reason));
    }
    return ok_status();
  }
  Error failure(const char* what) const { return Error(fmt::format("{}: cannot {}: {}", path_, what, sqlite3_errmsg(db_))); }

  sqlite3* db_ = nullptr;
  sqlite3_stmt* insert_ = nullptr;
  std::string path_;
};

}  // namespace

struct BagWriter::State {
  fs::path folder;
  std::string file;  // the storage file's name in the folder
  BagStorage storage = BagStorage::kMcap;
  std::unique_ptr<mcap::McapWriter> mcap;
  std::unique_ptr<SqliteBag> sqlite;
  struct Topic {
    std::string type;
    int64_t id = 0;  // MCAP channel or sqlite topic id
    uint64_t count = 0;
  };
  std::map<std::string, Topic> topics;
  int64_t first_ns = 0;
  int64_t last_ns = 0;
  uint64_t messages = 0;
  std::map<std::string, std::string> custom_data;
  bool closed = false;
};

BagWriter::BagWriter(std::unique_ptr<State> state) : state_(std::move(state)) {}
BagWriter::~BagWriter() {
  if (!state_->closed) (void)close();
}

Result<std::unique_ptr<BagWriter>> BagWriter::create(const std::string& folder, BagStorage storage) {
  std::error_code error;
  if (fs::exists(folder, error)) return Error(fmt::format("{}: exists; a ROS 2 bag is written into a new folder", folder));
  if (!fs::create_directories(folder, error)) return Error(fmt::format("{}: cannot create the folder: {}", folder, error.message()));
  auto state = std::make_unique<State>();
  state->folder = folder;
  state->storage = storage;
  state->file = fs::path(folder).lexically_normal().filename().string();
  if (state->file.empty()) state->file = fs::path(folder).lexically_normal().parent_path().filename().string();
  if (storage == BagStorage::kSqlite3) {
    state->file += "_0.db3";
    HANZO_ASSIGN_OR_RETURN(state->sqlite, SqliteBag::open((state->folder / state->file).string()));
  } else {
    state->file += "_0.mcap";
    mcap::McapWriterConfig config;
    config.profile = "ros2";
    HANZO_ASSIGN_OR_RETURN(state->mcap, mcap::McapWriter::open((state->folder / state->file).string(), config));
  }
  return std::unique_ptr<BagWriter>(new BagWriter(std::move(state)));
}

Status BagWriter::write(const std::string& topic, const std::string& type, Timestamp record_time, const std::string& cdr) {
  State& s = *state_;
  if (s.closed) return Error("ROS 2 bag writer: already closed");
  auto it = s.topics.find(topic);
  if (it == s.topics.end()) {
    const std::string text = schema_text(type);
    if (text.empty()) return Error(fmt::format("ROS 2 bag writer: type '{}' of topic {} is not one it writes", type, topic));
    int64_t id = 0;
    if (s.sqlite) {
      HANZO_ASSIGN_OR_RETURN(id, s.sqlite->add_topic(topic, type));
    } else {
      uint16_t schema = 0;
      HANZO_ASSIGN_OR_RETURN(schema, s.mcap->add_schema(type, "ros2msg", text));
      HANZO_ASSIGN_OR_RETURN(id, s.mcap->add_channel(schema, topic, "cdr", {{"offered_qos_profiles", ""}}));
    }
    it = s.topics.emplace(topic, State::Topic{type, id, 0}).first;
  } else if (it->second.type != type) {
    return Error(fmt::format("ROS 2 bag writer: topic {} has type {}, not {}", topic, it->second.type, type));
  }
  const int64_t ns = record_time.nanoseconds();
  if (ns < 0) return Error(fmt::format("ROS 2 bag writer: record time {} ns is before 1970", ns));
  if (s.sqlite) {
    HANZO_RETURN_IF_ERROR(s.sqlite->add_message(it->second.id, ns, cdr));
  } else {
    HANZO_RETURN_IF_ERROR(s.mcap->write(static_cast<uint16_t>(it->second.id), static_cast<uint64_t>(ns), static_cast<uint64_t>(ns), cdr));
  }
  s.first_ns = s.messages == 0 ? ns : std::min(s.first_ns, ns);
  s.last_ns = s.messages == 0 ? ns : std::max(s.last_ns, ns);
  ++s.messages;
  ++it->second.count;
  return ok_status();
}

void BagWriter::set_custom_data(std::map<std::string, std::string> custom_data) { state_->custom_data = std::move(custom_data); }

Status BagWriter::close() {
  State& s = *state_;
  if (s.closed) return ok_status();
  s.closed = true;
  if (s.mcap) HANZO_RETURN_IF_ERROR(s.mcap->close());
  std::string topics;
  for (const auto& [name, topic] : s.topics) {
    topics += fmt::format("    - topic_metadata:\n        name: {}\n        type: {}\n        serialization_format: cdr\n"
                          "        offered_qos_profiles: \"\"\n      message_count: {}\n", name, topic.type, topic.count);
  }
  std::string metadata = fmt::format(
      "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: {storage}\n  duration:\n    nanoseconds: {duration}\n"
      "  starting_time:\n    nanoseconds_since_epoch: {start}\n  message_count: {count}\n  topics_with_message_count:{topics}\n"
      "  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n    - {file}\n  files:\n"
      "    - path: {file}\n      starting_time:\n        nanoseconds_since_epoch: {start}\n      duration:\n"
      "        nanoseconds: {duration}\n      message_count: {count}\n",
      fmt::arg("duration", s.last_ns - s.first_ns), fmt::arg("start", s.first_ns), fmt::arg("count", s.messages),
      fmt::arg("topics", topics.empty() ? " []" : "\n" + topics.substr(0, topics.size() - 1)), fmt::arg("file", s.file),
      fmt::arg("storage", s.sqlite ? "sqlite3" : "mcap"));
  // Values as YAML double-quoted scalars (JSON strings are: the escapes are YAML's too).
  if (!s.custom_data.empty()) metadata += "  custom_data:\n";
  for (const auto& [key, value] : s.custom_data) metadata += fmt::format("    {}: {}\n", nlohmann::json(key).dump(), nlohmann::json(value).dump());
  if (s.sqlite) {
    const Status committed = s.sqlite->close(metadata);
    s.sqlite.reset();
    HANZO_RETURN_IF_ERROR(committed);
  }
  std::ofstream out(s.folder / "metadata.yaml", std::ios::binary);
  out << metadata;
  out.close();
  if (!out) return Error(fmt::format("{}: cannot write metadata.yaml", s.folder.string()));
  return ok_status();
}

}  // namespace hanzo::fusion::io::ros2
