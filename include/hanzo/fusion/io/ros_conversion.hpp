#pragma once
// ROS messages, serialized the ROS 1 way (bags) or as CDR (ROS 2: rosbag2, DDS), decoded into
// hanzo-fusion messages. The message layouts are the same in both ROS versions except
// std_msgs/Header (ROS 2 has no seq); ROS 2 type names carry "/msg/" ("sensor_msgs/msg/Imu").
//
//   sensor_msgs/Imu            -> ImuMessage (orientation kept unless orientation_covariance[0]
//                                 == -1; a covariance all zero ("unknown") or with [0] == -1 is
//                                 left out)
//   sensor_msgs/NavSatFix      -> GnssMessage (status -1 NO_FIX, 0/1 FIX_3D, 2 (GBAS) RTK_FIXED;
//                                 covariance kept unless its type is UNKNOWN; ENU as in ROS)
//   sensor_msgs/PointCloud2    -> PointCloudMessage: fields x, y, z (float32/float64); intensity
//                                 ("intensity"/"i", scaled to [0, 1]: /255 for values above 1);
//                                 ring ("ring"/"line"/"channel"); per-point time from "time"/"t"/
//                                 "timestamp"/"time_stamp"/"offset_time" as the drivers write it:
//                                   float seconds after the stamp (Velodyne),
//                                   integer nanoseconds after the stamp (Ouster "t", Livox offset_time),
//                                   float absolute seconds (Hesai, Robosense; kept to the microsecond),
//                                   float absolute nanoseconds (Livox ROS 2 "timestamp"),
//                                 absolute meaning within a day of the header stamp.
//                                 Non-finite points are dropped.
//   sensor_msgs/Image          -> ImageMessage (rgb8, bgr8, mono8, 8UC1, 16UC1/mono16 -> depth16,
//                                 32FC1 -> depth32f; row padding removed)
//   sensor_msgs/CompressedImage-> ImageMessage: JPEG or PNG decoded (colour -> bgr8, grey -> mono8,
//                                 16-bit grey -> depth16); image_transport's compressedDepth PNG
//                                 (a 12-byte header first) of 16UC1 depth -> depth16
//   sensor_msgs/CameraInfo     -> CameraInfo: K and D as intrinsics and distortion (plumb_bob /
//                                 rational_polynomial with k4..k6 zero -> radtan, equidistant)
//   nav_msgs/Odometry,
//   geometry_msgs/TwistStamped -> twist (forward speed, yaw rate), turned into cumulative
//                                 left/right wheel distances by WheelDistanceIntegrator
//   tf2_msgs/TFMessage         -> FrameTransforms (T_parent_child of each TransformStamped)
//   vision_msgs/Detection2DArray (vision_msgs 3 and 4: ROS 2 Galactic and later; CDR only)
//                              -> RosDetections: per detection its most likely class, box, id
//   vision_msgs/LabelInfo      -> LabelTable (class id -> class name of a detector/segmenter)
//
// Every decoder fails on truncated or inconsistent data, naming the type and what is wrong.

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::io::ros {

/// How the message bytes are serialized: ROS 1 (bags v2.0) or CDR (ROS 2, with its 4-byte
/// encapsulation header).
enum class Serialization { kRos1, kCdr };

/// "sensor_msgs/msg/Imu" -> "sensor_msgs/Imu" (ROS 1 names are returned as they are).
std::string normalized_type(std::string_view type);

Result<msgs::ImuMessage> imu_from_ros(std::string_view data, Serialization serialization);
Result<msgs::GnssMessage> gnss_from_ros(std::string_view data, Serialization serialization);
/// sensor_msgs/Range (radiation_type, field_of_view, min_range, max_range, range).
Result<msgs::RangeMessage> range_from_ros(std::string_view data, Serialization serialization);
Result<msgs::PointCloudMessage> point_cloud_from_ros(std::string_view data, Serialization serialization);
Result<msgs::ImageMessage> image_from_ros(std::string_view data, Serialization serialization);
Result<msgs::ImageMessage> compressed_image_from_ros(std::string_view data, Serialization serialization);

/// What hanzo-fusion uses of a sensor_msgs/CameraInfo.
struct CameraInfo {
  Timestamp stamp;
  std::string frame_id;
  calib::CameraCalibration camera;  ///< intrinsics with width and height, distortion
};
/// Fails for a K that is zero (an uncalibrated camera) and for distortion it cannot represent.
Result<CameraInfo> camera_info_from_ros(std::string_view data, Serialization serialization);

/// One geometry_msgs/TransformStamped: maps child-frame coordinates into the parent frame.
struct FrameTransform {
  Timestamp stamp;
  std::string parent_frame;
  std::string child_frame;
  SE3 T_parent_child;
};
/// tf2_msgs/TFMessage. Fails for a rotation that is not a unit quaternion (within 1e-3).
Result<std::vector<FrameTransform>> transforms_from_ros(std::string_view data, Serialization serialization);

/// One vision_msgs/Detection2D: the hypothesis of the highest score and the box.
struct RosDetection {
  std::string class_id;  ///< ObjectHypothesis.class_id as sent: a name ("person") or a LabelInfo id ("0")
  double score = 0.0;
  double center_x = 0.0, center_y = 0.0;  ///< bbox.center, pixels (x right, y down)
  double theta = 0.0;                     ///< bbox.center.theta, rad (0: axis-aligned)
  double size_x = 0.0, size_y = 0.0;      ///< bbox size, pixels
  std::string id;                         ///< Detection2D.id (a tracker's id); may be empty
};
/// A vision_msgs/Detection2DArray (stamp and frame of its header).
struct RosDetections {
  Timestamp stamp;
  std::string frame_id;
  std::vector<RosDetection> detections;
};
/// Fails for ROS 1 data (vision_msgs 1.x has another layout), truncated data and a detection
/// without any class hypothesis.
Result<RosDetections> detections_from_ros(std::string_view data, Serialization serialization);

/// A vision_msgs/LabelInfo: the class names of a detector's or segmenter's ids.
struct LabelTable {
  Timestamp stamp;
  std::string frame_id;
  std::map<uint16_t, std::string> class_names;  ///< class_map: class_id -> class_name
  float threshold = 0.0F;
};
/// Fails for ROS 1 data, truncated data and an empty class name.
Result<LabelTable> label_info_from_ros(std::string_view data, Serialization serialization);

/// What hanzo-fusion uses of a nav_msgs/Odometry or geometry_msgs/TwistStamped: the body twist.
struct OdometryTwist {
  Timestamp stamp;
  std::string child_frame_id;  ///< Odometry's child_frame_id, TwistStamped's header.frame_id
  double forward_speed = 0.0;  ///< twist.linear.x, m/s
  double yaw_rate = 0.0;       ///< twist.angular.z, rad/s
};
Result<OdometryTwist> odometry_twist_from_ros(std::string_view data, Serialization serialization);
Result<OdometryTwist> twist_stamped_from_ros(std::string_view data, Serialization serialization);

/// Integrates the twist of consecutive odometry messages into cumulative wheel distances of a
/// differential-drive base: v_left = v - w b / 2, v_right = v + w b / 2, distances by the
/// trapezoid rule between message times. The first message gives distances 0.
class WheelDistanceIntegrator {
 public:
  explicit WheelDistanceIntegrator(double wheel_separation) : wheel_separation_(wheel_separation) {}
  /// Fails (and changes nothing) for a stamp not after the previous one.
  Result<msgs::WheelOdometryMessage> add(const OdometryTwist& twist);

 private:
  double wheel_separation_;
  std::optional<OdometryTwist> previous_;
  double left_ = 0.0;
  double right_ = 0.0;
};

}  // namespace hanzo::fusion::io::ros
