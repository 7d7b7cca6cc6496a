#pragma once
// The calibration of imported ROS sensors from what a bag carries: /tf_static transforms and
// sensor_msgs/CameraInfo intrinsics (rosbag_import.hpp).

#include <string>
#include <vector>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/io/ros_conversion.hpp"

namespace hanzo::fusion::io::ros {

/// An imported sensor: its name in the log and the frame_id of its messages.
struct ImportedSensor {
  std::string name;
  std::string ros_topic;
  std::string frame_id;
  bool is_camera = false;
  bool is_imu = false;
};

struct CameraInfoOnTopic {
  std::string ros_topic;
  CameraInfo info;
};

struct StaticCalibration {
  std::string body_frame;
  calib::Calibration calibration;
  std::vector<std::string> notes;
};

/// Places each sensor by the static transform tree (T_body_sensor = T_body_frame), cameras with
/// the intrinsics of the CameraInfo of their frame_id (else of their topic namespace). The body
/// frame is `body_frame` or, when empty, base_link, base_footprint, the first IMU's frame, the
/// first camera's frame, the first sensor's frame. Sensors whose frame the tree does not
/// connect to the body frame are left out with a note; a camera without CameraInfo is placed
/// without intrinsics, with a note.
StaticCalibration static_calibration(const std::vector<ImportedSensor>& sensors, const std::vector<FrameTransform>& transforms,
                                     const std::vector<CameraInfoOnTopic>& camera_infos, const std::string& body_frame);

}  // namespace hanzo::fusion::io::ros
