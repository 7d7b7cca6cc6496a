#include "semantic_projection.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include "hanzo/fusion/pipeline/dynamic_mask.hpp"

namespace hanzo::fusion::pipeline {
namespace {

// Outputs kept per camera: enough for sweeps up to kMaxGap_s behind the newest image at 30 Hz.
constexpr std::size_t kKeptOutputs = 8;

}  // namespace

SemanticProjection::SemanticProjection(std::vector<Camera> cameras, const SE3& T_body_lidar, config::DynamicObjectsConfig dynamic_objects)
    : cameras_(std::move(cameras)), T_body_lidar_(T_body_lidar), dynamic_objects_(std::move(dynamic_objects)), outputs_(cameras_.size()) {}

const SemanticProjection::Camera* SemanticProjection::camera(std::string_view sensor) const {
  const auto found = std::find_if(cameras_.begin(), cameras_.end(), [sensor](const Camera& camera) { return camera.sensor == sensor; });
  return found == cameras_.end() ? nullptr : &*found;
}

void SemanticProjection::add(const Camera& camera, const msgs::DetectionsMessage& output,
                             const std::function<uint16_t(std::string_view)>& class_index) {
  const auto index = static_cast<std::size_t>(&camera - cameras_.data());
  Output kept;
  kept.body_time = output.timestamp + camera.time_offset;
  if (!output.segmentation.empty()) {
    std::array<uint16_t, 256> map_class;
    map_class.fill(msgs::kNoClass);
    for (std::size_t id = 0; id < output.segmentation_classes.size(); ++id) map_class[id] = class_index(output.segmentation_classes[id]);
    kept.classes.resize(output.segmentation.size());
    std::transform(output.segmentation.begin(), output.segmentation.end(), kept.classes.begin(), [&map_class](uint8_t id) { return map_class[id]; });
  }
  if (Result<DynamicMask> mask = dynamic_mask(output, camera.image_size, dynamic_objects_)) kept.static_mask = std::move(mask->static_mask);
  std::deque<Output>& outputs = outputs_[index];
  // Keep time order (a late output goes before newer ones).
  const auto after = std::upper_bound(outputs.begin(), outputs.end(), kept.body_time, [](Timestamp time, const Output& o) { return time < o.body_time; });
  outputs.insert(after, std::move(kept));
  if (outputs.size() > kKeptOutputs) outputs.pop_front();
}

SemanticProjection::Labelled SemanticProjection::label(Timestamp sweep_time, const std::vector<Eigen::Vector3f>& points_lidar,
                                                       const std::function<std::optional<SE3>(Timestamp)>& pose_at) const {
  Labelled result;
  if (std::all_of(outputs_.begin(), outputs_.end(), [](const std::deque<Output>& outputs) { return outputs.empty(); })) return result;
  result.classes.assign(points_lidar.size(), msgs::kNoClass);
  result.moving.assign(points_lidar.size(), 0);
  const std::optional<SE3> T_world_body_sweep = pose_at(sweep_time);
  for (std::size_t c = 0; c < cameras_.size(); ++c) {
    const std::deque<Output>& outputs = outputs_[c];
    const auto nearest = std::min_element(outputs.begin(), outputs.end(), [sweep_time](const Output& a, const Output& b) {
      return std::abs((a.body_time - sweep_time).seconds()) < std::abs((b.body_time - sweep_time).seconds());
    });
    if (nearest == outputs.end() || std::abs((nearest->body_time - sweep_time).seconds()) > kMaxGap_s) continue;
    if (nearest->classes.empty() && nearest->static_mask.empty()) continue;
    const Camera& camera = cameras_[c];
    SE3 T_sweep_image;  // body at the image time, in the body frame at the sweep time
    if (const std::optional<SE3> T_world_body_image = pose_at(nearest->body_time); T_world_body_sweep && T_world_body_image) {
      T_sweep_image = T_world_body_sweep->inverse() * *T_world_body_image;
    }
    const SE3 T_camera_lidar = (T_sweep_image * camera.T_body_camera).inverse() * T_body_lidar_;
    const Eigen::Matrix3d rotation = T_camera_lidar.rotation().matrix();
    const Eigen::Vector3d translation = T_camera_lidar.translation();
    const int width = camera.image_size.width, height = camera.image_size.height;
    for (std::size_t i = 0; i < points_lidar.size(); ++i) {
      const Eigen::Vector3d point_camera = rotation * points_lidar[i].cast<double>() + translation;
      if (point_camera.z() <= 0.05) continue;
      const std::optional<Eigen::Vector2d> pixel = camera.lens.project(point_camera);
      if (!pixel) continue;
      const int u = static_cast<int>(std::lround(pixel->x())), v = static_cast<int>(std::lround(pixel->y()));
      if (u < 0 || v < 0 || u >= width || v >= height) continue;
      const std::size_t at = static_cast<std::size_t>(v) * static_cast<std::size_t>(width) + static_cast<std::size_t>(u);
      if (!nearest->static_mask.empty() && nearest->static_mask.data[at] == 0) result.moving[i] = 1;
      if (!nearest->classes.empty() && result.classes[i] == msgs::kNoClass) result.classes[i] = nearest->classes[at];
    }
  }
  for (std::size_t i = 0; i < points_lidar.size(); ++i) {
    result.labelled += result.classes[i] != msgs::kNoClass;
    result.moving_points += result.moving[i];
  }
  return result;
}

}  // namespace hanzo::fusion::pipeline
