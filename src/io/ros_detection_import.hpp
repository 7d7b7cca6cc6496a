#pragma once
// A detector's outputs in a ROS bag turned into the msgs::DetectionsMessage of each camera image
// (rosbag_import.cpp): boxes from vision_msgs/Detection2DArray, dense labels from a label image
// (sensor_msgs/Image, one class id per pixel), class names from vision_msgs/LabelInfo. The boxes
// and the label image of one image come on different topics; DetectionMerger joins them into
// one message per image.

#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/ros_conversion.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::io::ros {

/// Detection2D.id (a tracker's id) -> track_id: a decimal id is kept, any other text gets the
/// next free number of this import; empty -> -1.
class TrackIds {
 public:
  int64_t track_id(const std::string& id);

 private:
  std::map<std::string, int64_t> named_;
};

/// The boxes of one Detection2DArray for an image of width x height pixels: a class id that the
/// label table names becomes that name; rotated boxes become the axis-aligned box around them;
/// boxes are clipped to the image. Fails for a box wholly outside the image.
Result<std::vector<msgs::Detection2D>> boxes_in_image(const RosDetections& array, const LabelTable* labels, uint32_t width,
                                                      uint32_t height, TrackIds& track_ids);

/// A label image's class ids and the label table they index.
struct Segmentation {
  std::vector<uint8_t> class_ids;  ///< width x height, msgs::kUnlabelledPixel where unlabelled
  std::vector<std::string> classes;
};
/// A label image (mono8 / 8UC1, or 16UC1 / mono16 ids) for an image of width x height pixels:
/// 255 (and 65535) are unlabelled; a label image of another size but the same aspect ratio
/// (within 1 %) is scaled pixel by pixel (nearest). Class names from the label table (ids it
/// leaves out named by their number), or the ids' numbers without one. Fails for another
/// encoding, another aspect ratio and class ids 254 to 65534.
Result<Segmentation> segmentation_in_image(const msgs::ImageMessage& label_image, const LabelTable* labels, uint32_t width, uint32_t height);

/// The camera a detector's topic belongs to, as the log has it.
struct DetectionCamera {
  std::string log_topic;  ///< the camera's log topic; its detections go to log_topic + "/detections"
  std::string sensor_name;
  uint32_t width = 0;
  uint32_t height = 0;
};

/// One detections message complete for the log.
struct ReadyDetections {
  std::string log_topic;  ///< camera topic + "/detections"
  std::string sensor_name;
  std::string source;     ///< the first ROS topic that contributed (where a refusal is counted)
  msgs::DetectionsMessage message;
};

/// Joins the boxes and label images of several ROS topics (sources) per camera image. A source
/// is attached to the camera of its first output. An image's message is complete when every
/// source attached to its camera, and every source not attached yet, has either contributed to
/// it or sent a later image's output (so an output a detector skipped never holds the others
/// up), or when the camera has output for an image more than kMaxLag_s later.
class DetectionMerger {
 public:
  static constexpr double kMaxLag_s = 1.0;

  /// A source whose camera is not known yet (before its first output).
  void expect(const std::string& source) { unattached_.insert(source); }
  /// `source`'s boxes and/or segmentation for the image of `camera` at `stamp` (the image's
  /// time in the log); returns the messages complete now, oldest first.
  std::vector<ReadyDetections> add(const std::string& source, const DetectionCamera& camera, Timestamp stamp, const std::string& frame_id,
                                   std::vector<msgs::Detection2D> boxes, std::optional<Segmentation> segmentation);
  /// Every message still open (at the end of the bag).
  std::vector<ReadyDetections> flush();

 private:
  struct Pending {
    ReadyDetections ready;
    std::set<std::string> sources;
  };
  std::vector<ReadyDetections> take_complete(const std::string& camera_topic);

  std::set<std::string> unattached_;
  std::map<std::string, std::set<std::string>> sources_of_camera_;  // camera log topic -> sources
  std::map<std::string, Timestamp> latest_of_source_;
  std::map<std::string, std::map<Timestamp, Pending>> pending_;     // camera log topic -> by image time
};

}  // namespace hanzo::fusion::io::ros
