#pragma once
// ROS bags -> sensor log: ROS 1 bags (v2.0) and ROS 2 bags (rosbag2: MCAP or SQLite storage,
// ros2_bag.hpp). The topics of supported types (ros_conversion.hpp) become channels of the log,
// named by a topic map ("/imu/data" -> "/imu") or by default "/" + the last part of the ROS
// topic ("/velodyne_points", "/hesai/pandar" -> "/pandar"), where generic last parts (data,
// data_raw, raw, points, fix, twist, compressed, and image* of cameras) give way to the
// namespace ("/imu/data" -> "/imu", "/ouster/points" -> "/ouster", "/camera/left/image_raw" ->
// "/left", "/cam0/image_raw/compressed" -> "/cam0"); a name taken by an earlier topic -> the
// whole ROS topic with '_' for '/' ("/camera/image_raw/compressed" -> "/camera_image_raw_compressed").
// The sensor name of each channel is its log topic without the leading '/'.
//
// A detector's and segmenter's output (HIP-0081) goes to the detections of the camera image it
// is for (`<camera log topic>/detections`, msgs::DetectionsMessage on the camera's sensor name):
// vision_msgs/Detection2DArray boxes, and label images: sensor_msgs/Image topics whose name holds
// "segment", "semantic" or "label" (mono8 class ids, 255 unlabelled; 16UC1 ids up to 253),
// or any Image topic the topic map sends to "<camera>/detections". Its camera: the one the topic
// map names (--topic /yolo/detections=/front/detections), else the camera topic of the same
// frame_id, then of the longest shared namespace. Class ids are named by the vision_msgs/LabelInfo
// of the longest shared namespace (or the bag's only one). The boxes and label image of one image
// (matched by header stamp) are joined into one message; an output whose camera has no image
// yet, a box wholly outside the image or a label image of another aspect ratio is rejected
// (counted on its topic with the reason).
//
// Calibration: /tf_static (tf2_msgs/TFMessage) and sensor_msgs/CameraInfo topics are not
// written to the log; they give each imported sensor's T_body_sensor (the static transform tree
// from the body frame to the frame_id of the sensor's messages) and each camera's intrinsics
// (the CameraInfo of the same frame_id, or of the same topic namespace).

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/ros1_bag.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"

namespace hanzo::fusion::io {

struct RosbagImportConfig {
  /// ROS topic -> log topic. When not empty, only these ROS topics are imported (calibration
  /// topics are read all the same).
  std::map<std::string, std::string> topic_map;
  /// Wheel separation (m) of the differential-drive base; needed to import nav_msgs/Odometry
  /// and geometry_msgs/TwistStamped as wheel odometry.
  std::optional<double> wheel_separation;
  /// Use the bag's record time instead of header.stamp (also used when a stamp is zero).
  bool use_record_time = false;
  /// The frame the calibration's transforms map into. Empty: base_link, else base_footprint,
  /// else the frame of the first IMU topic, else of the first camera, else of the first sensor.
  std::string body_frame;
  /// Log topic -> sensor name of its channel (default: the topic without its leading '/').
  std::map<std::string, std::string> sensor_names;
};

struct TopicImportReport {
  std::string ros_topic;
  std::string ros_type;
  std::string topic;          ///< in the log
  std::string frame_id;       ///< of its first message
  uint64_t imported = 0;
  uint64_t rejected = 0;      ///< messages that did not decode or failed validation
  std::string first_rejection;  ///< the reason of the first rejected message
};

struct RosbagImportReport {
  std::string storage;       ///< "ros1" (a ROS 1 bag), "mcap" or "sqlite3" (ROS 2 storage)
  uint64_t messages = 0;     ///< messages in the bag, imported or not
  ros1::BagSummary bag;      ///< ROS 1 bags: chunks and their compressions
  std::vector<std::string> warnings;                     ///< e.g. a cut-off storage file, read to its last chunk
  std::vector<TopicImportReport> topics;                 ///< imported topics, by ROS topic
  std::map<std::string, std::string> skipped_topics;     ///< ROS topic -> type, unsupported or not selected
  std::map<std::string, uint64_t> calibration_topics;    ///< /tf_static and CameraInfo topics -> messages read

  std::string body_frame;           ///< the calibration's body frame; empty when nothing was found
  calib::Calibration calibration;   ///< imported sensors placed by /tf_static, cameras with intrinsics
  std::vector<std::string> calibration_notes;  ///< what could not be placed, and why
};

/// A ROS 2 bag written by `hanzo-fusion export ros2bag` carries, in metadata.yaml's custom_data,
/// what the log called its topics and sensors (`hanzo_fusion.sensors`: a JSON object ROS topic ->
/// sensor name), the wheels' separation (`hanzo_fusion.wheel_separation`, m), the calibration
/// it was exported with (`hanzo_fusion.calibration`, the calibration YAML) and the label images'
/// detections topics (`hanzo_fusion.label_images`: ROS topic -> log topic). import_rosbag2 then
/// gives back the same log: topics and sensor names kept (unless `topic_map` names others), the
/// wheel separation used unless given, and that calibration (time offsets and all) instead of the
/// one rebuilt from /tf_static.
///
/// Imports every message of the selected topics of a ROS 1 bag, in bag order (odometry twists
/// are integrated into wheel distances in stamp order: recorders store messages by arrival, in
/// which odometry stamps may go back; equal stamps are rejected). Messages that do
/// not decode or fail validation are counted per topic (with the first reason) and left out;
/// the import fails for a malformed bag, a topic-map entry naming a topic the bag lacks or of a
/// type that cannot be imported, odometry without a wheel separation, or a write error.
Result<RosbagImportReport> import_rosbag(const std::string& path, SensorLogWriter& writer, const RosbagImportConfig& config);

/// The same for a ROS 2 bag: a folder with metadata.yaml, or one .mcap / .db3 storage file.
/// Topics in a serialization other than cdr (or ros1 in MCAP) are skipped and listed.
Result<RosbagImportReport> import_rosbag2(const std::string& path, SensorLogWriter& writer, const RosbagImportConfig& config);

}  // namespace hanzo::fusion::io
