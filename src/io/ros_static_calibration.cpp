#include "ros_static_calibration.hpp"

#include <map>
#include <optional>

#include <fmt/format.h>

namespace hanzo::fusion::io::ros {
namespace {

// The static transform tree: each frame's parent and T_parent_child.
class FrameTree {
 public:
  explicit FrameTree(const std::vector<FrameTransform>& transforms) {
    for (const FrameTransform& t : transforms) parents_[t.child_frame] = {t.parent_frame, t.T_parent_child};
  }
  bool knows(const std::string& frame) const {
    if (parents_.count(frame) != 0) return true;
    for (const auto& [child, parent] : parents_) {
      if (parent.first == frame) return true;
    }
    return false;
  }
  // T_frame1_frame2 when both hang in the same tree.
  std::optional<SE3> transform(const std::string& frame1, const std::string& frame2) const {
    const auto [root1, T_root_frame1] = to_root(frame1);
    const auto [root2, T_root_frame2] = to_root(frame2);
    if (root1 != root2) return std::nullopt;
    return T_root_frame1.inverse() * T_root_frame2;
  }

 private:
  std::pair<std::string, SE3> to_root(std::string frame) const {
    SE3 T_root_frame;
    for (int depth = 0; depth < 256; ++depth) {  // a cycle in a bad bag ends here
      const auto parent = parents_.find(frame);
      if (parent == parents_.end()) break;
      T_root_frame = parent->second.second * T_root_frame;
      frame = parent->second.first;
    }
    return {frame, T_root_frame};
  }
  std::map<std::string, std::pair<std::string, SE3>> parents_;
};

std::string topic_namespace(const std::string& topic) {
  const auto slash = topic.find_last_of('/');
  return slash == std::string::npos ? "" : topic.substr(0, slash);
}

std::string choose_body_frame(const std::vector<ImportedSensor>& sensors, const FrameTree& tree) {
  for (const char* frame : {"base_link", "base_footprint"}) {
    if (tree.knows(frame)) return frame;
  }
  for (const auto& wanted : {&ImportedSensor::is_imu, &ImportedSensor::is_camera}) {
    for (const ImportedSensor& sensor : sensors) {
      if (sensor.*wanted && !sensor.frame_id.empty()) return sensor.frame_id;
    }
  }
  for (const ImportedSensor& sensor : sensors) {
    if (!sensor.frame_id.empty()) return sensor.frame_id;
  }
  return "";
}

const CameraInfo* camera_info_for(const ImportedSensor& camera, const std::vector<CameraInfoOnTopic>& infos) {
  for (const CameraInfoOnTopic& info : infos) {
    if (info.info.frame_id == camera.frame_id) return &info.info;
  }
  // image_transport publishes ".../image_raw" (and ".../image_raw/compressed") beside ".../camera_info".
  for (std::string space = topic_namespace(camera.ros_topic); !space.empty(); space = topic_namespace(space)) {
    for (const CameraInfoOnTopic& info : infos) {
      if (topic_namespace(info.ros_topic) == space) return &info.info;
    }
  }
  return nullptr;
}

}  // namespace

StaticCalibration static_calibration(const std::vector<ImportedSensor>& sensors, const std::vector<FrameTransform>& transforms,
                                     const std::vector<CameraInfoOnTopic>& camera_infos, const std::string& body_frame) {
  StaticCalibration result;
  const FrameTree tree(transforms);
  result.body_frame = body_frame.empty() ? choose_body_frame(sensors, tree) : body_frame;
  if (result.body_frame.empty()) return result;
  for (const ImportedSensor& sensor : sensors) {
    std::optional<SE3> T_body_sensor;
    if (sensor.frame_id == result.body_frame) T_body_sensor = SE3::identity();
    else if (!sensor.frame_id.empty()) T_body_sensor = tree.transform(result.body_frame, sensor.frame_id);
    if (!T_body_sensor) {
      result.notes.push_back(fmt::format("{} (frame '{}'): /tf_static does not connect it to '{}'; left out", sensor.name,
                                         sensor.frame_id, result.body_frame));
      continue;
    }
    calib::SensorCalibration entry = calib::SensorCalibration::from_transform(sensor.name, *T_body_sensor);
    if (sensor.is_camera) {
      if (const CameraInfo* info = camera_info_for(sensor, camera_infos)) {
        entry.camera = info->camera;
      } else {
        result.notes.push_back(fmt::format("{}: no CameraInfo of frame '{}'; placed without intrinsics", sensor.name, sensor.frame_id));
      }
    }
    // A CameraInfo that contradicts its images (principal point outside them, ...) is left out.
    if (Status valid = calib::validate(calib::Calibration{{entry}}); !valid && entry.camera) {
      result.notes.push_back(fmt::format("{}: CameraInfo left out: {}", sensor.name, valid.error().message));
      entry.camera.reset();
    }
    result.calibration.sensors.push_back(std::move(entry));
  }
  return result;
}

}  // namespace hanzo::fusion::io::ros
