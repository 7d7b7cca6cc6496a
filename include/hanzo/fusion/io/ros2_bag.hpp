#pragma once
// ROS 2 bags (rosbag2) without a ROS installation: a bag folder with metadata.yaml and its
// storage files, or one storage file on its own.
//
//   storage "mcap"    : MCAP files (profile ros2; schemas "pkg/msg/Type", encoding cdr), read by
//                       io/mcap.hpp (chunk CRCs checked, cut-off files read to the last chunk)
//   storage "sqlite3" : .db3 files: tables topics(id, name, type, serialization_format) and
//                       messages(topic_id, timestamp, data), the layout of every ROS 2 release
//   compression       : rosbag2's zstd, per file (FILE: "x.mcap.zstd", decompressed into a
//                       temporary file that is removed afterwards) or per message (MESSAGE)
//
// Messages are handed over in record-time order per storage file, files in metadata.yaml's
// order (rosbag2 splits a recording into consecutive files). A folder without metadata.yaml
// (a recording cut off before rosbag2 wrote it) is read from its .mcap / .db3 files in name
// order. Errors name the file and what is wrong: a missing or unreadable metadata.yaml entry,
// an unknown storage, a file that is not MCAP or not a rosbag2 SQLite database.

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::io::ros2 {

struct Topic {
  std::string name;                  ///< e.g. "/imu/data"
  std::string type;                  ///< as stored, e.g. "sensor_msgs/msg/Imu"
  std::string serialization_format;  ///< "cdr" for ROS 2 data; MCAP files may hold "ros1"
};

struct BagMessage {
  const Topic* topic = nullptr;
  int64_t record_time_ns = 0;  ///< when the recorder received it
  std::string_view data;       ///< the serialized message, valid during the callback
};

struct Bag {
  std::string storage;              ///< "mcap" or "sqlite3"
  std::string compression;          ///< "" or "zstd"
  std::string compression_mode;     ///< "" , "FILE" or "MESSAGE"
  std::vector<std::string> files;   ///< storage files, in reading order
  std::vector<Topic> topics;        ///< every topic of every file, by name
  std::map<std::string, std::string> custom_data;  ///< metadata.yaml's custom_data (the recorder's own keys)
};

struct BagSummary {
  uint64_t messages = 0;
  /// Set when a storage file had to be recovered (an MCAP without summary, cut off).
  std::vector<std::string> warnings;
};

/// Reads metadata.yaml (or finds the storage files) and the topics of every storage file.
Result<Bag> open_bag(const std::string& path);

/// Calls `on_message` for every message of the bag; an error from it stops the read with that
/// error. Fails naming the file for a storage file that cannot be read.
Result<BagSummary> read_bag(const Bag& bag, const std::function<Status(const BagMessage&)>& on_message);

}  // namespace hanzo::fusion::io::ros2
