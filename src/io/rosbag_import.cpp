#include "hanzo/fusion/io/rosbag_import.hpp"

#include <set>
#include <type_traits>

#include <fmt/format.h>

#include "hanzo/fusion/io/ros1_conversion.hpp"
#include "hanzo/fusion/msgs/validate.hpp"

namespace hanzo::fusion::io {
namespace {

bool supported(const std::string& type) {
  return type == "sensor_msgs/Imu" || type == "sensor_msgs/NavSatFix" || type == "sensor_msgs/PointCloud2" ||
         type == "sensor_msgs/Image" || type == "nav_msgs/Odometry";
}

std::string default_topic(const std::string& ros_topic) {
  const auto slash = ros_topic.find_last_of('/');
  return "/" + (slash == std::string::npos ? ros_topic : ros_topic.substr(slash + 1));
}

// The decoded message with its time replaced by stamp(time) (per-point times move along).
template <typename Message, typename StampFunction>
Result<msgs::SensorMessage> restamped(Result<Message> message, const StampFunction& stamp) {
  if (!message) return message.error();
  const Duration shift = stamp(message->timestamp) - message->timestamp;
  message->timestamp += shift;
  if constexpr (std::is_same_v<Message, msgs::PointCloudMessage>) {
    for (Timestamp& t : message->point_timestamps) t += shift;
  }
  return msgs::SensorMessage(std::move(*message));
}

struct TopicState {
  TopicImportReport report;
  std::optional<ros1::WheelDistanceIntegrator> wheels;
};

}  // namespace

Result<RosbagImportReport> import_rosbag(const std::string& path, SensorLogWriter& writer, const RosbagImportConfig& config) {
  std::map<uint32_t, ros1::Connection> connections;
  HANZO_ASSIGN_OR_RETURN(connections, ros1::read_bag_connections(path));
  RosbagImportReport report;
  std::map<std::string, TopicState> topics;  // by ROS topic
  std::set<std::string> bag_topics;
  for (const auto& [id, connection] : connections) {
    bag_topics.insert(connection.topic);
    const bool selected = config.topic_map.empty() || config.topic_map.count(connection.topic) != 0;
    if (!selected || !supported(connection.type)) {
      report.skipped_topics[connection.topic] = connection.type;
      continue;
    }
    if (topics.count(connection.topic) != 0) continue;  // several publishers of one topic
    TopicState state;
    state.report.ros_topic = connection.topic;
    state.report.ros_type = connection.type;
    const auto mapped = config.topic_map.find(connection.topic);
    state.report.topic = mapped == config.topic_map.end() ? default_topic(connection.topic) : mapped->second;
    if (connection.type == "nav_msgs/Odometry") {
      if (!config.wheel_separation || !(*config.wheel_separation > 0.0)) {
        return Error(fmt::format("{}: topic {} is nav_msgs/Odometry: give the wheel separation of the base "
                                 "(--wheel-separation METRES) to import it as wheel odometry, or leave it out",
                                 path, connection.topic));
      }
      state.wheels.emplace(*config.wheel_separation);
    }
    topics.emplace(connection.topic, std::move(state));
  }
  for (const auto& [ros_topic, topic] : config.topic_map) {
    if (bag_topics.count(ros_topic) == 0) return Error(fmt::format("{}: the bag has no topic '{}'", path, ros_topic));
    if (topics.count(ros_topic) == 0) {
      return Error(fmt::format("{}: topic '{}' has type {}, which cannot be imported", path, ros_topic, report.skipped_topics[ros_topic]));
    }
  }

  auto on_message = [&](const ros1::BagMessage& message) -> Status {
    const auto it = topics.find(message.connection->topic);
    if (it == topics.end()) return ok_status();
    TopicState& state = it->second;
    const std::string& type = message.connection->type;
    const Timestamp record_time = Timestamp::from_nanoseconds(message.record_time.nanoseconds());
    auto stamp = [&](Timestamp header_stamp) { return config.use_record_time || header_stamp.is_zero() ? record_time : header_stamp; };
    Result<msgs::SensorMessage> converted = Error("");
    if (type == "sensor_msgs/Imu") {
      converted = restamped(ros1::imu_from_ros(message.data), stamp);
    } else if (type == "sensor_msgs/NavSatFix") {
      converted = restamped(ros1::gnss_from_ros(message.data), stamp);
    } else if (type == "sensor_msgs/PointCloud2") {
      converted = restamped(ros1::point_cloud_from_ros(message.data), stamp);
    } else if (type == "sensor_msgs/Image") {
      converted = restamped(ros1::image_from_ros(message.data), stamp);
    } else {  // nav_msgs/Odometry
      auto twist = ros1::odometry_twist_from_ros(message.data);
      if (twist) twist->stamp = stamp(twist->stamp);
      converted = twist ? restamped(state.wheels->add(*twist), [](Timestamp t) { return t; }) : Error(twist.error());
    }
    // A message that does not decode or validate is left out and counted; only a failure to
    // write the log ends the import.
    const Status valid = converted ? std::visit([](const auto& m) { return msgs::validate(m); }, *converted)
                                   : Status(converted.error());
    if (!valid) {
      if (state.report.rejected++ == 0) {
        state.report.first_rejection = fmt::format("at {} ns: {}", record_time.nanoseconds(), valid.error().message);
      }
      return ok_status();
    }
    HANZO_RETURN_IF_ERROR(writer.write(state.report.topic, *converted, state.report.topic.substr(1)));
    ++state.report.imported;
    return ok_status();
  };
  HANZO_ASSIGN_OR_RETURN(report.bag, ros1::read_bag(path, on_message));
  for (auto& [ros_topic, state] : topics) report.topics.push_back(std::move(state.report));
  return report;
}

}  // namespace hanzo::fusion::io
