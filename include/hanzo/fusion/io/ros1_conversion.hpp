#pragma once
// ROS1-serialized messages (little-endian; strings and variable arrays prefixed with a uint32
// length; time = uint32 sec + uint32 nsec) decoded into hanzo-fusion messages:
//
//   sensor_msgs/Imu         -> ImuMessage (orientation kept unless orientation_covariance[0] == -1;
//                              a covariance all zero ("unknown") or with [0] == -1 is left out)
//   sensor_msgs/NavSatFix   -> GnssMessage (status -1 NO_FIX, 0/1 FIX_3D, 2 (GBAS) RTK_FIXED;
//                              covariance kept unless its type is UNKNOWN; ENU as in ROS)
//   sensor_msgs/PointCloud2 -> PointCloudMessage (fields x, y, z as float32/float64; optional
//                              intensity (scaled to [0, 1]: /255 for values above 1), ring, and
//                              per-point time as "time"/"t"/"timestamp" offsets from the header
//                              stamp (float seconds, or integer ns); non-finite points dropped)
//   sensor_msgs/Image       -> ImageMessage (rgb8, bgr8, mono8, 16UC1/mono16 -> depth16,
//                              32FC1 -> depth32f; row padding removed)
//   nav_msgs/Odometry       -> twist (forward speed, yaw rate), turned into cumulative left/right
//                              wheel distances of a differential-drive base by WheelDistanceIntegrator.
//
// Every decoder fails on truncated or inconsistent data, naming what is wrong.

#include <optional>
#include <string>
#include <string_view>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::io::ros1 {

Result<msgs::ImuMessage> imu_from_ros(std::string_view data);
Result<msgs::GnssMessage> gnss_from_ros(std::string_view data);
Result<msgs::PointCloudMessage> point_cloud_from_ros(std::string_view data);
Result<msgs::ImageMessage> image_from_ros(std::string_view data);

/// What hanzo-fusion uses of a nav_msgs/Odometry: the body-frame twist.
struct OdometryTwist {
  Timestamp stamp;
  std::string child_frame_id;
  double forward_speed = 0.0;  ///< twist.linear.x, m/s
  double yaw_rate = 0.0;       ///< twist.angular.z, rad/s
};
Result<OdometryTwist> odometry_twist_from_ros(std::string_view data);

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

}  // namespace hanzo::fusion::io::ros1
