#pragma once
// Writing ROS 2 bags (rosbag2 folders: metadata.yaml + one MCAP file, profile "ros2", schemas
// as ROS 2 message definitions ("ros2msg"), messages as little-endian CDR) of what hanzo-fusion
// produces, so that trajectories and maps open in RViz 2 (`ros2 bag play`) and Foxglove:
//
//   geometry_msgs/msg/PoseStamped, geometry_msgs/msg/PoseWithCovarianceStamped, nav_msgs/msg/Path,
//   sensor_msgs/msg/PointCloud2 (x, y, z float32 [+ intensity float32]), nav_msgs/msg/OccupancyGrid;
//   and sensor data (a sensor log as a ROS 2 bag): sensor_msgs/msg/Imu, NavSatFix, Image, CompressedImage,
//   PointCloud2 in a LiDAR driver's layout, geometry_msgs/msg/TwistStamped, a detector's output
//   as vision_msgs/msg/Detection2DArray, LabelInfo and label images; the calibration as
//   tf2_msgs/msg/TFMessage (/tf_static) and sensor_msgs/msg/CameraInfo.
//
// The *_cdr functions encode one message (ROS 2 Humble layouts, as read back by Foxglove's
// @foxglove/rosmsg2-serialization in tests/io/rosbag2_export_conformance_test.cpp).

#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/io/ros_conversion.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::io::ros2 {

struct StampedPose {
  Timestamp stamp;
  msgs::Pose pose;
};

std::string pose_stamped_cdr(Timestamp stamp, const std::string& frame_id, const msgs::Pose& pose);
/// `covariance`: ROS's row-major 6x6 over (x, y, z, rotation about X, Y, Z), all in `frame_id`.
std::string pose_with_covariance_stamped_cdr(Timestamp stamp, const std::string& frame_id, const msgs::Pose& pose,
                                             const Eigen::Matrix<double, 6, 6>& covariance);
/// The path's header carries `stamp`; each pose its own.
std::string path_cdr(Timestamp stamp, const std::string& frame_id, const std::vector<StampedPose>& poses);
/// An unorganized cloud (height 1); `intensities` empty or one per point.
std::string point_cloud_cdr(Timestamp stamp, const std::string& frame_id, const std::vector<Eigen::Vector3f>& points,
                            const std::vector<float>& intensities);
/// A 2D layer (size_z 1): probability p -> round(100 p), unknown (exactly 0.5) -> -1. Fails for
/// a 3D layer (flatten it first: maps/map_export.hpp) or a layer whose cells do not fill it.
Result<std::string> occupancy_grid_cdr(Timestamp stamp, const std::string& frame_id, const msgs::OccupancyGridLayer& layer);

/// Point layouts of the common ROS 2 LiDAR drivers (ros_conversion.hpp reads them all):
///   kPlain    x y z intensity (float32), ring (uint16), time (float32 s after the stamp)
///   kVelodyne the same (velodyne_pointcloud)
///   kOuster   x y z, intensity at 16, t (uint32 ns after the stamp), reflectivity, ring (uint16)
///   kLivox    x y z intensity (float32), tag, line (uint8), timestamp (float64 absolute ns)
///   kHesai    x y z, intensity at 16, timestamp (float64 absolute s) at 24, ring (uint16) at 32
/// Intensities are written as stored ([0, 1]); missing rings are 0, missing point times the stamp.
enum class LidarLayout { kPlain, kVelodyne, kOuster, kLivox, kHesai };
Result<LidarLayout> lidar_layout_from_name(const std::string& name);

std::string imu_cdr(const msgs::ImuMessage& imu);
/// NO_FIX -> status -1, FIX_2D/3D -> 0, RTK_FLOAT/FIXED -> 2 (GBAS); covariance "known" when given.
std::string navsatfix_cdr(const msgs::GnssMessage& fix, const std::string& frame_id);
/// rgb8, bgr8, mono8, 16UC1 (depth16), 32FC1 (depth32f).
std::string image_cdr(const msgs::ImageMessage& image);
/// sensor_msgs/CompressedImage holding `file` (a JPEG or PNG of `image`'s pixels; `image` gives
/// stamp, frame and encoding), format as image_transport writes it: "<encoding>; jpeg compressed
/// <encoding>" ("png" alike), e.g. "mono8; jpeg compressed mono8".
std::string compressed_image_cdr(const msgs::ImageMessage& image, const std::string& format, const std::string& file);
std::string point_cloud_cdr(const msgs::PointCloudMessage& cloud, LidarLayout layout);
/// A detector's boxes as vision_msgs/msg/Detection2DArray (vision_msgs 4): one hypothesis per
/// box (class name as class_id, score), the box as centre and size, track_id as id ("" for -1).
/// Instance masks are left out (vision_msgs has none).
std::string detection_array_cdr(const msgs::DetectionsMessage& detections);
/// The segmentation as a label image (sensor_msgs/msg/Image, mono8 class ids, 255 unlabelled).
std::string label_image_cdr(const msgs::DetectionsMessage& detections);
/// The segmentation's label table as vision_msgs/msg/LabelInfo (class id i = classes[i]).
std::string label_info_cdr(Timestamp stamp, const std::string& frame_id, const std::vector<std::string>& classes);
/// tf2_msgs/TFMessage: one TransformStamped per transform (header frame = parent).
std::string tf_message_cdr(const std::vector<ros::FrameTransform>& transforms);
/// sensor_msgs/CameraInfo of an image of `width` x `height`: K, R = I, P = [K | 0]; distortion
/// "plumb_bob" (k1 k2 p1 p2 k3; none: zeros) or "equidistant" (k1..k4).
std::string camera_info_cdr(Timestamp stamp, const std::string& frame_id, const calib::CameraCalibration& camera, uint32_t width,
                            uint32_t height);
/// Forward speed (m/s) and yaw rate (rad/s) as geometry_msgs/TwistStamped.
std::string twist_stamped_cdr(Timestamp stamp, const std::string& frame_id, double forward_speed, double yaw_rate);

/// The storage of a bag: MCAP (ROS 2 Iron and later record it; Humble with its MCAP plugin) or
/// sqlite3 (.db3, the default of Foxy to Humble), both read by `ros2 bag play` and Foxglove.
enum class BagStorage { kMcap, kSqlite3 };
/// "mcap", "sqlite3".
Result<BagStorage> bag_storage_from_name(const std::string& name);

/// Writes one bag folder. Not thread-safe.
class BagWriter {
 public:
  /// Creates `folder` (which must not exist, as with `ros2 bag record -o`) and its storage file
  /// (MCAP with each type's message definition as its schema; sqlite3 in ROS 2 Humble's layout:
  /// tables schema, metadata, topics, messages).
  static Result<std::unique_ptr<BagWriter>> create(const std::string& folder, BagStorage storage = BagStorage::kMcap);
  ~BagWriter();
  BagWriter(const BagWriter&) = delete;
  BagWriter& operator=(const BagWriter&) = delete;

  /// `type` one of the types above ("nav_msgs/msg/Path"); `cdr` from its encoder. The record
  /// time is the message's log time in the bag.
  Status write(const std::string& topic, const std::string& type, Timestamp record_time, const std::string& cdr);
  /// Strings for metadata.yaml's `custom_data` (rosbag2's map of the recorder's own keys); what
  /// the importer reads back (import_rosbag2: `hanzo_fusion.*` keys).
  void set_custom_data(std::map<std::string, std::string> custom_data);
  /// Finishes the storage file and writes metadata.yaml (topics with counts, start, duration,
  /// custom_data).
  Status close();

 private:
  struct State;
  explicit BagWriter(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

}  // namespace hanzo::fusion::io::ros2
