#include "hanzo/fusion/io/rosbag_import.hpp"

#include <algorithm>
#include <cstdlib>
#include <deque>
#include <tuple>
#include <set>
#include <type_traits>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/io/ros2_bag.hpp"
#include "hanzo/fusion/io/ros_conversion.hpp"
#include "hanzo/fusion/msgs/validate.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "ros_detection_import.hpp"
#include "ros_static_calibration.hpp"
#include "ros_wire_reader.hpp"

namespace hanzo::fusion::io {
namespace {

// A detector stamps its output with its image's header stamp; this much apart still matches.
constexpr double kSameImage_s = 1e-3;
// Images per camera whose times are kept for the detections that come after them.
constexpr std::size_t kRecentImages = 64;

// Types written to the log (normalized ROS 1 names).
const std::set<std::string> kSensorTypes = {"sensor_msgs/Imu",      "sensor_msgs/NavSatFix",       "sensor_msgs/PointCloud2",
                                            "sensor_msgs/Image",    "sensor_msgs/CompressedImage", "nav_msgs/Odometry",
                                            "geometry_msgs/TwistStamped", "sensor_msgs/Range",   "vision_msgs/Detection2DArray"};
bool is_camera(const std::string& type) { return type == "sensor_msgs/Image" || type == "sensor_msgs/CompressedImage"; }
// Types that are not written as they are: read for the calibration or the detections' class names.
bool is_side_information(const std::string& type, const std::string& ros_topic) {
  return type == "sensor_msgs/CameraInfo" || type == "vision_msgs/LabelInfo" || (type == "tf2_msgs/TFMessage" && ros_topic == "/tf_static");
}
bool is_odometry(const std::string& type) { return type == "nav_msgs/Odometry" || type == "geometry_msgs/TwistStamped"; }
// Parts of an Image topic's name that make it a label image (rosbag_import.hpp).
constexpr const char* kLabelImageNames[] = {"segment", "semantic", "label"};

std::vector<std::string> topic_parts(const std::string& ros_topic) {
  std::vector<std::string> parts;
  for (std::size_t start = 0; start <= ros_topic.size();) {
    const std::size_t slash = std::min(ros_topic.find('/', start), ros_topic.size());
    if (slash > start) parts.push_back(ros_topic.substr(start, slash - start));
    start = slash + 1;
  }
  return parts;
}

bool ends_with(const std::string& text, std::string_view suffix) {
  return text.size() >= suffix.size() && text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// A segmenter's label image: an Image topic mapped to a camera's detections, or named so
// (rosbag_import.hpp).
bool is_label_image(const std::string& ros_topic, const std::string& type, const std::map<std::string, std::string>& topic_map) {
  if (type != "sensor_msgs/Image") return false;
  if (const auto mapped = topic_map.find(ros_topic); mapped != topic_map.end()) return ends_with(mapped->second, config::kDetectionsTopicSuffix);
  std::string lower = ros_topic;
  std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return std::any_of(std::begin(kLabelImageNames), std::end(kLabelImageNames),
                     [&lower](const char* name) { return lower.find(name) != std::string::npos; });
}

// How many leading namespace parts two topics share ("/camera/detections", "/camera/image_raw": 1).
std::size_t shared_namespace(const std::string& a, const std::string& b) {
  const std::vector<std::string> x = topic_parts(a), y = topic_parts(b);
  std::size_t n = 0;
  while (n + 1 < x.size() && n + 1 < y.size() && x[n] == y[n]) ++n;
  return n;
}

// The log topic of a ROS topic when the topic map does not name one (rosbag_import.hpp).
std::string default_topic(const std::string& ros_topic, const std::string& type, const std::set<std::string>& taken) {
  // Drivers' generic last names say less than their namespace: "/imu/data", "/ouster/points".
  static const std::set<std::string> kGeneric = {"data", "data_raw", "raw", "points", "fix", "twist", "compressed"};
  std::vector<std::string> parts = topic_parts(ros_topic);
  while (parts.size() > 1 && (kGeneric.count(parts.back()) != 0 || (is_camera(type) && parts.back().rfind("image", 0) == 0))) {
    parts.pop_back();
  }
  const std::string name = "/" + (parts.empty() ? std::string("topic") : parts.back());
  if (taken.count(name) == 0) return name;
  std::string whole;
  for (const std::string& part : topic_parts(ros_topic)) whole += (whole.empty() ? "" : "_") + part;
  return "/" + whole;
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

// The frame of a decoded message; GNSS fixes keep none, so theirs comes from the ROS header.
std::string frame_of(const msgs::SensorMessage& message, std::string_view data, ros::Serialization serialization) {
  return std::visit(
      [&](const auto& m) {
        if constexpr (requires { m.frame_id; }) {
          return m.frame_id;
        } else {
          ros::WireReader r(data, serialization);
          return r.header().second;
        }
      },
      message);
}

// Turns the messages of one bag (ROS 1 or ROS 2) into log messages and the calibration.
class TopicImporter {
 public:
  TopicImporter(std::string path, SensorLogWriter& writer, const RosbagImportConfig& config)
      : path_(std::move(path)), writer_(writer), config_(config) {}

  // Called for every topic of the bag before its messages; `serialization` empty when the
  // topic's serialization cannot be read.
  Status add_topic(const std::string& ros_topic, const std::string& stored_type, std::optional<ros::Serialization> serialization) {
    bag_topics_.insert(ros_topic);
    const std::string type = ros::normalized_type(stored_type);
    if (serialization && is_side_information(type, ros_topic)) {
      calibration_topics_[ros_topic] = {type, *serialization};
      report_.calibration_topics[ros_topic] = 0;
      return ok_status();
    }
    const bool selected = config_.topic_map.empty() || config_.topic_map.count(ros_topic) != 0;
    const bool boxes = type == "vision_msgs/Detection2DArray";
    const bool ros1_boxes = boxes && serialization == ros::Serialization::kRos1;
    if (!selected || !serialization || kSensorTypes.count(type) == 0 || ros1_boxes) {
      report_.skipped_topics[ros_topic] = !serialization ? stored_type + " (serialization not readable)"
                                          : ros1_boxes  ? stored_type + " (ROS 1 layout: not read)"
                                                        : stored_type;
      return ok_status();
    }
    if (topics_.count(ros_topic) != 0) return ok_status();  // several publishers of one topic
    TopicState state;
    state.type = type;
    state.serialization = *serialization;
    state.report.ros_topic = ros_topic;
    state.report.ros_type = stored_type;
    state.kind = boxes ? Kind::kBoxes : is_label_image(ros_topic, type, config_.topic_map) ? Kind::kLabelImage : Kind::kSensor;
    if (state.kind != Kind::kSensor) merger_.expect(ros_topic);
    if (is_odometry(type)) {
      if (!config_.wheel_separation || !(*config_.wheel_separation > 0.0)) {
        return Error(fmt::format("{}: topic {} is {}: give the wheel separation of the base (--wheel-separation METRES) to "
                                 "import it as wheel odometry, or leave it out", path_, ros_topic, type));
      }
      state.wheels.emplace(*config_.wheel_separation);
    }
    topics_.emplace(ros_topic, std::move(state));
    return ok_status();
  }

  // After all add_topic calls: names the log topics and checks the topic map.
  Status finish_topics() {
    for (const auto& [ros_topic, topic] : config_.topic_map) {
      if (bag_topics_.count(ros_topic) == 0) return Error(fmt::format("{}: the bag has no topic '{}'", path_, ros_topic));
      if (topics_.count(ros_topic) == 0) {
        const auto skipped = report_.skipped_topics.find(ros_topic);
        const std::string type = skipped != report_.skipped_topics.end() ? skipped->second : calibration_topics_[ros_topic].first;
        return Error(fmt::format("{}: topic '{}' has type {}, which cannot be imported", path_, ros_topic, type));
      }
    }
    std::set<std::string> taken;
    for (auto& [ros_topic, state] : topics_) {  // mapped names first: defaults must not take them
      const auto mapped = config_.topic_map.find(ros_topic);
      if (mapped != config_.topic_map.end() && state.kind == Kind::kSensor) taken.insert(state.report.topic = mapped->second);
    }
    for (auto& [ros_topic, state] : topics_) {
      if (state.report.topic.empty() && state.kind == Kind::kSensor) taken.insert(state.report.topic = default_topic(ros_topic, state.type, taken));
    }
    // A detector's topic mapped to a camera's detections names that camera (its topic in the log).
    for (const auto& [ros_topic, state] : topics_) {
      const auto mapped = config_.topic_map.find(ros_topic);
      if (state.kind == Kind::kSensor || mapped == config_.topic_map.end()) continue;
      const std::string& target = mapped->second;
      const std::size_t camera_length = target.size() - std::min(target.size(), config::kDetectionsTopicSuffix.size());
      const bool camera_named = ends_with(target, config::kDetectionsTopicSuffix) &&
                                std::any_of(topics_.begin(), topics_.end(), [&](const auto& topic) {
                                  return topic.second.kind == Kind::kSensor && is_camera(topic.second.type) &&
                                         topic.second.report.topic == target.substr(0, camera_length);
                                });
      if (!camera_named) {
        return Error(fmt::format("{}: topic '{}' is a detector's output: map it to the detections of a camera topic of the log "
                                 "(CAMERA{}), not to '{}'", path_, ros_topic, config::kDetectionsTopicSuffix, target));
      }
    }
    return ok_status();
  }

  // One message; only a failure to write the log is an error.
  Status on_message(const std::string& ros_topic, int64_t record_time_ns, std::string_view data) {
    ++report_.messages;
    const Timestamp record_time = Timestamp::from_nanoseconds(record_time_ns);
    if (const auto calibration = calibration_topics_.find(ros_topic); calibration != calibration_topics_.end()) {
      read_calibration(ros_topic, calibration->second.first, calibration->second.second, data);
      return ok_status();
    }
    const auto it = topics_.find(ros_topic);
    if (it == topics_.end()) return ok_status();
    TopicState& state = it->second;
    if (state.kind != Kind::kSensor) return on_detector_output(state, ros_topic, record_time_ns, data);
    if (is_odometry(state.type)) {
      // Twists are integrated in stamp order once all are read: recorders store by arrival,
      // in which odometry stamps may go back.
      auto twist = state.type == "nav_msgs/Odometry" ? ros::odometry_twist_from_ros(data, state.serialization)
                                                     : ros::twist_stamped_from_ros(data, state.serialization);
      if (!twist) return reject(state, record_time_ns, twist.error().message);
      twist->stamp = stamp(twist->stamp, record_time);
      state.twists.push_back({record_time_ns, *twist});
      return ok_status();
    }
    return write(state, record_time_ns, convert(state, record_time, data), data);
  }

  // After the last message: integrates and writes the odometry topics.
  Status flush() {
    for (auto& [ros_topic, state] : topics_) {
      std::stable_sort(state.twists.begin(), state.twists.end(),
                       [](const auto& a, const auto& b) { return a.second.stamp < b.second.stamp; });
      for (const auto& [record_time_ns, twist] : state.twists) {
        Result<msgs::WheelOdometryMessage> wheels = state.wheels->add(twist);
        HANZO_RETURN_IF_ERROR(write(state, record_time_ns, wheels ? Result<msgs::SensorMessage>(*wheels) : wheels.error(), {}));
      }
      state.twists.clear();
    }
    return write_detections(merger_.flush());
  }

  RosbagImportReport finish() {
    std::vector<ros::ImportedSensor> sensors;
    for (auto& [ros_topic, state] : topics_) {
      if (state.report.imported > 0 && state.kind == Kind::kSensor) {
        sensors.push_back({sensor_name(state.report.topic), ros_topic, state.report.frame_id, is_camera(state.type),
                           state.type == "sensor_msgs/Imu"});
      }
      report_.topics.push_back(std::move(state.report));
    }
    ros::StaticCalibration calibration = ros::static_calibration(sensors, transforms_, camera_infos_, config_.body_frame);
    report_.body_frame = calibration.body_frame;
    report_.calibration = std::move(calibration.calibration);
    report_.calibration_notes.insert(report_.calibration_notes.end(), calibration.notes.begin(), calibration.notes.end());
    if (Status valid = calib::validate(report_.calibration); !valid) {
      report_.calibration_notes.push_back("no calibration: " + valid.error().message);
      report_.calibration.sensors.clear();
    }
    return std::move(report_);
  }

 private:
  // A sensor's messages, or a detector's output for a camera: boxes or label images.
  enum class Kind { kSensor, kBoxes, kLabelImage };

  struct TopicState {
    std::string type;  // normalized
    Kind kind = Kind::kSensor;
    ros::Serialization serialization = ros::Serialization::kRos1;
    TopicImportReport report;
    std::optional<ros::WheelDistanceIntegrator> wheels;
    std::vector<std::pair<int64_t, ros::OdometryTwist>> twists;  // odometry: (record time ns, twist) until flush()
    // Cameras: the latest image's size and the recent images' (header stamp, time in the log).
    uint32_t image_width = 0;
    uint32_t image_height = 0;
    std::deque<std::pair<Timestamp, Timestamp>> recent_images;
    // A detector's topic: the camera its output belongs to, once chosen.
    const TopicState* camera = nullptr;
  };

  // The camera a detector's output belongs to (rosbag_import.hpp): the one its topic is mapped
  // to, else the camera of the same frame, then of the longest shared namespace, then the
  // shortest topic; only cameras with an image so far take part.
  Result<const TopicState*> camera_of(TopicState& source, const std::string& ros_topic, const std::string& frame_id) {
    if (source.camera != nullptr) return source.camera;
    const auto mapped = config_.topic_map.find(ros_topic);
    const TopicState* best = nullptr;
    std::tuple<bool, std::size_t, int64_t> best_rank;
    std::size_t cameras = 0;
    for (const auto& [topic, state] : topics_) {
      if (state.kind != Kind::kSensor || !is_camera(state.type) || state.report.imported == 0) continue;
      ++cameras;
      if (mapped != config_.topic_map.end()) {
        if (mapped->second == state.report.topic + std::string(config::kDetectionsTopicSuffix)) best = &state;
        continue;
      }
      const std::tuple<bool, std::size_t, int64_t> rank(state.report.frame_id == frame_id, shared_namespace(ros_topic, topic),
                                                        -static_cast<int64_t>(topic.size()));
      if (best == nullptr || rank > best_rank) {
        best = &state;
        best_rank = rank;
      }
    }
    if (best == nullptr) {
      return Error(mapped != config_.topic_map.end() ? fmt::format("no image of the camera of {} before it", mapped->second)
                                                     : std::string("no camera image before it"));
    }
    if (mapped == config_.topic_map.end() && cameras > 1 && !std::get<0>(best_rank) && std::get<1>(best_rank) == 0) {
      return Error(fmt::format("frame '{}' is no camera's and the topic shares no namespace with one: name its camera with "
                               "--topic {}=CAMERA{}", frame_id, ros_topic, config::kDetectionsTopicSuffix));
    }
    source.camera = best;
    source.report.topic = best->report.topic + std::string(config::kDetectionsTopicSuffix);
    return best;
  }

  // The class names for a detector's topic: the LabelInfo of the longest shared namespace, or
  // the only one of the bag.
  const ros::LabelTable* label_table_for(const std::string& ros_topic) const {
    const ros::LabelTable* best = nullptr;
    std::size_t best_shared = 0;
    for (const auto& [topic, table] : label_tables_) {
      const std::size_t shared = shared_namespace(ros_topic, topic);
      if (best == nullptr || shared > best_shared) {
        best = &table;
        best_shared = shared;
      }
    }
    return best_shared > 0 || label_tables_.size() == 1 ? best : nullptr;
  }

  // The time in the log of the camera image a detector's output stamped `header_stamp` is for.
  Timestamp image_time(const TopicState& camera, Timestamp header_stamp, Timestamp record_time) const {
    for (const auto& [header, logged] : camera.recent_images) {
      if (std::abs((header - header_stamp).seconds()) <= kSameImage_s) return logged;
    }
    return stamp(header_stamp, record_time);
  }

  // A Detection2DArray or label image: decoded, put on its camera's image, merged with the other
  // detector topics of that image, written when complete.
  Status on_detector_output(TopicState& state, const std::string& ros_topic, int64_t record_time_ns, std::string_view data) {
    std::optional<ros::RosDetections> boxes;
    std::optional<msgs::ImageMessage> label_image;
    Timestamp header_stamp;
    std::string frame_id;
    if (state.kind == Kind::kBoxes) {
      auto decoded = ros::detections_from_ros(data, state.serialization);
      if (!decoded) return reject(state, record_time_ns, decoded.error().message);
      header_stamp = decoded->stamp;
      frame_id = decoded->frame_id;
      boxes = std::move(*decoded);
    } else {
      auto decoded = ros::image_from_ros(data, state.serialization);
      if (!decoded) return reject(state, record_time_ns, decoded.error().message);
      header_stamp = decoded->timestamp;
      frame_id = decoded->frame_id;
      label_image = std::move(*decoded);
    }
    Result<const TopicState*> camera = camera_of(state, ros_topic, frame_id);
    if (!camera) return reject(state, record_time_ns, camera.error().message);
    const ros::DetectionCamera target{(*camera)->report.topic, sensor_name((*camera)->report.topic), (*camera)->image_width,
                                      (*camera)->image_height};
    const ros::LabelTable* labels = label_table_for(ros_topic);
    std::vector<msgs::Detection2D> detections;
    std::optional<ros::Segmentation> segmentation;
    if (boxes) {
      auto in_image = ros::boxes_in_image(*boxes, labels, target.width, target.height, track_ids_);
      if (!in_image) return reject(state, record_time_ns, "vision_msgs/Detection2DArray: " + in_image.error().message);
      detections = std::move(*in_image);
    } else {
      auto in_image = ros::segmentation_in_image(*label_image, labels, target.width, target.height);
      if (!in_image) return reject(state, record_time_ns, "label image: " + in_image.error().message);
      segmentation = std::move(*in_image);
    }
    if (state.report.imported++ == 0) state.report.frame_id = frame_id;
    const Timestamp time = image_time(**camera, header_stamp, Timestamp::from_nanoseconds(record_time_ns));
    return write_detections(merger_.add(ros_topic, target, time, frame_id, std::move(detections), std::move(segmentation)));
  }

  Status write_detections(std::vector<ros::ReadyDetections> ready) {
    for (ros::ReadyDetections& detections : ready) {
      if (Status valid = msgs::validate(detections.message); !valid) {
        TopicState& source = topics_.at(detections.source);
        HANZO_RETURN_IF_ERROR(reject(source, detections.message.timestamp.nanoseconds(), valid.error().message));
        continue;
      }
      HANZO_RETURN_IF_ERROR(writer_.write(detections.log_topic, msgs::SensorMessage(std::move(detections.message)), detections.sensor_name));
    }
    return ok_status();
  }

  // A camera's image written: its size and times for the detections that come for it.
  static void remember_image(TopicState& camera, Timestamp header_stamp, const msgs::ImageMessage& image) {
    camera.image_width = image.width;
    camera.image_height = image.height;
    camera.recent_images.emplace_back(header_stamp, image.timestamp);
    if (camera.recent_images.size() > kRecentImages) camera.recent_images.pop_front();
  }

  std::string sensor_name(const std::string& topic) const {
    const auto named = config_.sensor_names.find(topic);
    return named != config_.sensor_names.end() ? named->second : topic.substr(1);
  }

  Timestamp stamp(Timestamp header_stamp, Timestamp record_time) const {
    return config_.use_record_time || header_stamp.is_zero() ? record_time : header_stamp;
  }

  // Counts a message left out (did not decode or validate), keeping the first reason.
  Status reject(TopicState& state, int64_t record_time_ns, const std::string& reason) {
    if (state.report.rejected++ == 0) state.report.first_rejection = fmt::format("at {} ns: {}", record_time_ns, reason);
    return ok_status();
  }

  // Writes a converted message that validates; only a failure to write the log is an error.
  Status write(TopicState& state, int64_t record_time_ns, const Result<msgs::SensorMessage>& converted, std::string_view data) {
    const Status valid = converted ? std::visit([](const auto& m) { return msgs::validate(m); }, *converted)
                                   : Status(converted.error());
    if (!valid) return reject(state, record_time_ns, valid.error().message);
    if (state.report.imported == 0) state.report.frame_id = frame_of(*converted, data, state.serialization);
    HANZO_RETURN_IF_ERROR(writer_.write(state.report.topic, *converted, sensor_name(state.report.topic)));
    ++state.report.imported;
    if (const auto* image = std::get_if<msgs::ImageMessage>(&*converted)) {
      remember_image(state, ros::WireReader(data, state.serialization).header().first, *image);
    }
    return ok_status();
  }

  Result<msgs::SensorMessage> convert(const TopicState& state, Timestamp record_time, std::string_view data) const {
    auto stamp = [&](Timestamp header_stamp) { return this->stamp(header_stamp, record_time); };
    const ros::Serialization s = state.serialization;
    const std::string& type = state.type;
    if (type == "sensor_msgs/Imu") return restamped(ros::imu_from_ros(data, s), stamp);
    if (type == "sensor_msgs/NavSatFix") return restamped(ros::gnss_from_ros(data, s), stamp);
    if (type == "sensor_msgs/Range") return restamped(ros::range_from_ros(data, s), stamp);
    if (type == "sensor_msgs/PointCloud2") return restamped(ros::point_cloud_from_ros(data, s), stamp);
    if (type == "sensor_msgs/Image") return restamped(ros::image_from_ros(data, s), stamp);
    return restamped(ros::compressed_image_from_ros(data, s), stamp);  // sensor_msgs/CompressedImage
  }

  void read_calibration(const std::string& ros_topic, const std::string& type, ros::Serialization serialization, std::string_view data) {
    ++report_.calibration_topics[ros_topic];
    if (type == "vision_msgs/LabelInfo") {
      auto table = ros::label_info_from_ros(data, serialization);
      if (table) label_tables_[ros_topic] = std::move(*table);
      else if (camera_info_errors_.insert(ros_topic).second) report_.calibration_notes.push_back(ros_topic + ": " + table.error().message);
      return;
    }
    if (type == "sensor_msgs/CameraInfo") {
      auto info = ros::camera_info_from_ros(data, serialization);
      if (!info) {
        if (camera_info_errors_.insert(ros_topic).second) report_.calibration_notes.push_back(ros_topic + ": " + info.error().message);
        return;
      }
      for (const ros::CameraInfoOnTopic& known : camera_infos_) {
        if (known.ros_topic == ros_topic) return;  // the first one of a topic counts (they repeat with every image)
      }
      camera_infos_.push_back({ros_topic, std::move(*info)});
      return;
    }
    auto transforms = ros::transforms_from_ros(data, serialization);
    if (!transforms) {
      report_.calibration_notes.push_back(ros_topic + ": " + transforms.error().message);
      return;
    }
    transforms_.insert(transforms_.end(), transforms->begin(), transforms->end());
  }

  std::string path_;
  SensorLogWriter& writer_;
  const RosbagImportConfig& config_;
  RosbagImportReport report_;
  std::set<std::string> bag_topics_;
  std::map<std::string, TopicState> topics_;  // by ROS topic
  std::map<std::string, std::pair<std::string, ros::Serialization>> calibration_topics_;  // ROS topic -> type
  std::vector<ros::FrameTransform> transforms_;
  std::vector<ros::CameraInfoOnTopic> camera_infos_;
  std::set<std::string> camera_info_errors_;  // CameraInfo and LabelInfo topics whose error is noted
  std::map<std::string, ros::LabelTable> label_tables_;  // by LabelInfo topic, the latest message
  ros::TrackIds track_ids_;
  ros::DetectionMerger merger_;
};

}  // namespace

Result<RosbagImportReport> import_rosbag(const std::string& path, SensorLogWriter& writer, const RosbagImportConfig& config) {
  std::map<uint32_t, ros1::Connection> connections;
  HANZO_ASSIGN_OR_RETURN(connections, ros1::read_bag_connections(path));
  TopicImporter importer(path, writer, config);
  for (const auto& [id, connection] : connections) {
    HANZO_RETURN_IF_ERROR(importer.add_topic(connection.topic, connection.type, ros::Serialization::kRos1));
  }
  HANZO_RETURN_IF_ERROR(importer.finish_topics());
  ros1::BagSummary bag;
  HANZO_ASSIGN_OR_RETURN(bag, ros1::read_bag(path, [&](const ros1::BagMessage& message) {
    return importer.on_message(message.connection->topic, message.record_time.nanoseconds(), message.data);
  }));
  HANZO_RETURN_IF_ERROR(importer.flush());
  RosbagImportReport report = importer.finish();
  report.storage = "ros1";
  report.bag = bag;
  if (!bag.complete) report.warnings.push_back(fmt::format("{}: cut off; read up to the last complete record", path));
  return report;
}

namespace {

// What `hanzo-fusion export ros2bag` recorded of the log (rosbag_import.hpp): the configuration
// the import runs with, and the calibration to report (none when the bag carries none).
Result<std::optional<calib::Calibration>> apply_recorded_log(const ros2::Bag& bag, const std::string& path, RosbagImportConfig& config) {
  const auto recorded = [&](const char* key) -> std::optional<std::string> {
    const auto found = bag.custom_data.find(key);
    return found == bag.custom_data.end() ? std::nullopt : std::optional<std::string>(found->second);
  };
  const bool recorded_topics = config.topic_map.empty();  // unless the caller names the topics
  if (const std::optional<std::string> sensors = recorded("hanzo_fusion.sensors"); sensors && recorded_topics) {
    const nlohmann::json names = nlohmann::json::parse(*sensors, nullptr, false);
    if (!names.is_object()) return Error(fmt::format("{}: custom_data hanzo_fusion.sensors is not a JSON object", path));
    for (const auto& [topic, sensor] : names.items()) {
      if (!sensor.is_string()) return Error(fmt::format("{}: custom_data hanzo_fusion.sensors: '{}' has no sensor name", path, topic));
      config.topic_map[topic] = topic;
      config.sensor_names[topic] = sensor.get<std::string>();
    }
  }
  if (const std::optional<std::string> label_images = recorded("hanzo_fusion.label_images"); label_images && recorded_topics) {
    const nlohmann::json topics = nlohmann::json::parse(*label_images, nullptr, false);
    if (!topics.is_object()) return Error(fmt::format("{}: custom_data hanzo_fusion.label_images is not a JSON object", path));
    for (const auto& [ros_topic, detections] : topics.items()) {
      if (!detections.is_string()) return Error(fmt::format("{}: custom_data hanzo_fusion.label_images: '{}' has no log topic", path, ros_topic));
      config.topic_map.emplace(ros_topic, detections.get<std::string>());
    }
  }
  if (const std::optional<std::string> separation = recorded("hanzo_fusion.wheel_separation"); separation && !config.wheel_separation) {
    char* end = nullptr;
    const double metres = std::strtod(separation->c_str(), &end);
    if (end == separation->c_str() || !(metres > 0.0)) {
      return Error(fmt::format("{}: custom_data hanzo_fusion.wheel_separation '{}' is not a positive number", path, *separation));
    }
    config.wheel_separation = metres;
  }
  if (const std::optional<std::string> calibration = recorded("hanzo_fusion.calibration")) {
    calib::Calibration parsed;
    HANZO_ASSIGN_OR_RETURN(parsed, calib::parse_calibration(*calibration, path + " (custom_data hanzo_fusion.calibration)"));
    return std::optional<calib::Calibration>(std::move(parsed));
  }
  return std::optional<calib::Calibration>();
}

}  // namespace

Result<RosbagImportReport> import_rosbag2(const std::string& path, SensorLogWriter& writer, const RosbagImportConfig& given) {
  ros2::Bag bag;
  HANZO_ASSIGN_OR_RETURN(bag, ros2::open_bag(path));
  RosbagImportConfig config = given;
  std::optional<calib::Calibration> recorded_calibration;
  HANZO_ASSIGN_OR_RETURN(recorded_calibration, apply_recorded_log(bag, path, config));
  TopicImporter importer(path, writer, config);
  auto serialization_of = [](const std::string& format) -> std::optional<ros::Serialization> {
    if (format == "cdr") return ros::Serialization::kCdr;
    if (format == "ros1") return ros::Serialization::kRos1;
    return std::nullopt;
  };
  for (const ros2::Topic& topic : bag.topics) {
    HANZO_RETURN_IF_ERROR(importer.add_topic(topic.name, topic.type, serialization_of(topic.serialization_format)));
  }
  HANZO_RETURN_IF_ERROR(importer.finish_topics());
  ros2::BagSummary summary;
  HANZO_ASSIGN_OR_RETURN(summary, ros2::read_bag(bag, [&](const ros2::BagMessage& message) {
    return importer.on_message(message.topic->name, message.record_time_ns, message.data);
  }));
  HANZO_RETURN_IF_ERROR(importer.flush());
  RosbagImportReport report = importer.finish();
  report.storage = bag.storage;
  report.warnings = summary.warnings;
  if (recorded_calibration) {
    report.calibration = std::move(*recorded_calibration);
    report.calibration_notes.push_back("the calibration the bag was exported with (custom_data hanzo_fusion.calibration)");
  }
  return report;
}

}  // namespace hanzo::fusion::io
