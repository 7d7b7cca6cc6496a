#pragma once
// ROS1 bag -> sensor log: the topics of supported types (ros1_conversion.hpp) become channels
// of the log, named by a topic map ("/imu/data" -> "/imu") or "/<last part of the ROS topic>".

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/ros1_bag.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"

namespace hanzo::fusion::io {

struct RosbagImportConfig {
  /// ROS topic -> log topic. When not empty, only these ROS topics are imported.
  std::map<std::string, std::string> topic_map;
  /// Wheel separation (m) of the differential-drive base; needed to import nav_msgs/Odometry.
  std::optional<double> wheel_separation;
  /// Use the bag's record time instead of header.stamp (also used when a stamp is zero).
  bool use_record_time = false;
};

struct TopicImportReport {
  std::string ros_topic;
  std::string ros_type;
  std::string topic;          ///< in the log
  uint64_t imported = 0;
  uint64_t rejected = 0;      ///< messages that did not decode or failed validation
  std::string first_rejection;  ///< the reason of the first rejected message
};

struct RosbagImportReport {
  ros1::BagSummary bag;
  std::vector<TopicImportReport> topics;                 ///< imported topics, by ROS topic
  std::map<std::string, std::string> skipped_topics;     ///< ROS topic -> type, unsupported or not selected
};

/// Imports every message of the selected topics, in bag order. Messages that do not decode or
/// fail validation are counted per topic (with the first reason) and left out; the import
/// fails for a malformed bag, a topic-map entry naming a topic the bag lacks, Odometry without
/// a wheel separation, or a write error.
Result<RosbagImportReport> import_rosbag(const std::string& path, SensorLogWriter& writer, const RosbagImportConfig& config);

}  // namespace hanzo::fusion::io
