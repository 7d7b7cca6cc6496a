#pragma once
// ROS1 bag files, format 2.0 (http://wiki.ros.org/Bags/Format/2.0): records of
// <header_len><header: name=value fields><data_len><data>, messages in chunks that are stored
// uncompressed, bz2- or lz4-compressed. This reader walks the file once from the start, one
// chunk in memory at a time, and hands every message to a callback in file order (rosbag
// writes chunks in time order, so this is time order per topic for recorded bags).
//
// It needs no index: a bag whose recording was cut off (no index section) is read up to its
// last complete chunk. Malformed records are errors naming the byte offset.

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::io::ros1 {

struct Connection {
  uint32_t id = 0;
  std::string topic;
  std::string type;                ///< e.g. "sensor_msgs/Imu"
  std::string md5sum;
  std::string message_definition;  ///< the .msg text with its dependencies
};

/// A ROS time: seconds and nanoseconds.
struct Time {
  uint32_t sec = 0;
  uint32_t nsec = 0;
  int64_t nanoseconds() const { return static_cast<int64_t>(sec) * 1'000'000'000 + nsec; }
};

struct BagMessage {
  const Connection* connection = nullptr;
  Time record_time;       ///< the bag's record time (when rosbag received it)
  std::string_view data;  ///< ROS1-serialized message, valid during the callback
};

struct BagSummary {
  uint64_t chunks = 0;
  uint64_t messages = 0;
  std::map<std::string, uint64_t> chunk_compressions;  ///< "none", "bz2", "lz4" -> count
  bool complete = true;  ///< false when the file ended inside a record (cut-off recording)
};

/// Reads `path`, calling `on_message` for every message; `on_message` returning an error stops
/// the read with that error. Connections are known before their first message.
Result<BagSummary> read_bag(const std::string& path, const std::function<Status(const BagMessage&)>& on_message);

/// All connections of a bag (a read without messages).
Result<std::map<uint32_t, Connection>> read_bag_connections(const std::string& path);

}  // namespace hanzo::fusion::io::ros1
