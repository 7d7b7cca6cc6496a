// vision_msgs (ROS 2's detector and segmenter outputs) decoded for the import
// (ros_conversion.hpp). Layouts of vision_msgs 3.x / 4.x (Galactic, Humble, Jazzy):
//
//   Detection2DArray: Header header, Detection2D[] detections
//   Detection2D:      Header header, ObjectHypothesisWithPose[] results, BoundingBox2D bbox, string id
//   ObjectHypothesisWithPose: ObjectHypothesis hypothesis {string class_id, float64 score},
//                     geometry_msgs/PoseWithCovariance pose (7 + 36 float64)
//   BoundingBox2D:    Pose2D center {Point2D position {float64 x, y}, float64 theta},
//                     float64 size_x, size_y (3.x: geometry_msgs/Pose2D x, y, theta: the same bytes)
//   LabelInfo:        Header header, VisionClass[] class_map {uint16 class_id, string class_name},
//                     float32 threshold

#include <fmt/format.h>

#include "hanzo/fusion/io/ros_conversion.hpp"
#include "ros_wire_reader.hpp"

namespace hanzo::fusion::io::ros {
namespace {

Error malformed(const char* type) { return Error(fmt::format("{}: truncated or malformed message data", type)); }

Error not_ros1(const char* type) {
  return Error(fmt::format("{}: only the ROS 2 layout (vision_msgs 3 and later, CDR) is read", type));
}

// The fewest bytes a Detection2D and a hypothesis take on the wire: counts are checked against
// what is left before anything is allocated.
constexpr uint64_t kMinDetectionBytes = 8 + 4 + 4 + 40 + 4;
constexpr uint64_t kMinHypothesisBytes = 4 + 8 + 43 * 8;
constexpr uint64_t kMinVisionClassBytes = 2 + 4;

}  // namespace

Result<RosDetections> detections_from_ros(std::string_view data, Serialization serialization) {
  constexpr const char* kType = "vision_msgs/Detection2DArray";
  if (serialization != Serialization::kCdr) return not_ros1(kType);
  WireReader r(data, serialization);
  RosDetections array;
  std::tie(array.stamp, array.frame_id) = r.header();
  const uint32_t count = r.u32();
  if (!r.can_take(count * kMinDetectionBytes)) return malformed(kType);
  array.detections.reserve(count);
  for (uint32_t i = 0; i < count; ++i) {
    RosDetection detection;
    r.header();  // each detection repeats the array's stamp and frame
    const uint32_t hypotheses = r.u32();
    if (!r.can_take(hypotheses * kMinHypothesisBytes)) return malformed(kType);
    bool found = false;
    for (uint32_t k = 0; k < hypotheses; ++k) {
      std::string class_id = r.string();
      const double score = r.f64();
      for (int j = 0; j < 7 + 36; ++j) r.f64();  // pose and its covariance
      if (!found || score > detection.score) {
        detection.class_id = std::move(class_id);
        detection.score = score;
        found = true;
      }
    }
    detection.center_x = r.f64();
    detection.center_y = r.f64();
    detection.theta = r.f64();
    detection.size_x = r.f64();
    detection.size_y = r.f64();
    detection.id = r.string();
    if (!r.ok()) return malformed(kType);
    if (!found) return Error(fmt::format("{}: detections[{}] has no class hypothesis (results is empty)", kType, i));
    array.detections.push_back(std::move(detection));
  }
  if (!r.ok()) return malformed(kType);
  return array;
}

Result<LabelTable> label_info_from_ros(std::string_view data, Serialization serialization) {
  constexpr const char* kType = "vision_msgs/LabelInfo";
  if (serialization != Serialization::kCdr) return not_ros1(kType);
  WireReader r(data, serialization);
  LabelTable table;
  std::tie(table.stamp, table.frame_id) = r.header();
  const uint32_t count = r.u32();
  if (!r.can_take(count * kMinVisionClassBytes)) return malformed(kType);
  for (uint32_t i = 0; i < count; ++i) {
    const uint16_t id = r.u16();
    std::string name = r.string();
    if (!r.ok()) return malformed(kType);
    if (name.empty()) return Error(fmt::format("{}: class id {} has an empty name", kType, id));
    table.class_names[id] = std::move(name);
  }
  table.threshold = r.f32();
  if (!r.ok()) return malformed(kType);
  return table;
}

}  // namespace hanzo::fusion::io::ros
