#include "hanzo/fusion/msgs/map_validation.hpp"

#include <cmath>
#include <string>
#include <string_view>

#include <fmt/format.h>

#include "hanzo/fusion/core/geodesy.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::msgs {
namespace {

class MapChecker {
 public:
  explicit MapChecker(std::string_view message_name) : message_name_(message_name) {}

  Status fail(const std::string& field, std::string_view what) const {
    return Error{fmt::format("{}.{}: {}", message_name_, field, what), field};
  }

  Status finite(double value, const std::string& field) const {
    return std::isfinite(value) ? ok_status() : fail(field, fmt::format("non-finite value {}", value));
  }

  Status positive(double value, const std::string& field) const {
    if (!std::isfinite(value) || value <= 0.0) return fail(field, fmt::format("{} (expected > 0)", value));
    return ok_status();
  }

  template <typename Repeated>
  Status per_element(const Repeated& values, int count, const std::string& field, std::string_view element) const {
    if (values.size() != 0 && values.size() != count) {
      return fail(field, fmt::format("{} values for {} {} (expected none or one per {})", values.size(), count, element, element));
    }
    return ok_status();
  }

  template <typename Repeated>
  Status labels(const Repeated& values, const std::string& field) const {
    for (int i = 0; i < values.size(); ++i) {
      if (!v1::SemanticLabel_IsValid(values.Get(i))) return fail(fmt::format("{}[{}]", field, i), fmt::format("unknown label {}", values.Get(i)));
    }
    return ok_status();
  }

  // Segmentation classes: indices into a label table of class_count names, or kNoClass.
  template <typename Repeated>
  Status classes(const Repeated& values, uint64_t class_count, const std::string& field) const {
    for (int i = 0; i < values.size(); ++i) {
      const uint32_t value = values.Get(i);
      if (value != kNoClass && value >= class_count) {
        return fail(fmt::format("{}[{}]", field, i), fmt::format("class {} past the {} semantic_classes", value, class_count));
      }
    }
    return ok_status();
  }

  template <typename Points>
  Status points(const Points& values, const std::string& field) const {
    for (int i = 0; i < values.size(); ++i) {
      const v1::Point3& p = values.Get(i);
      if (!std::isfinite(p.x()) || !std::isfinite(p.y()) || !std::isfinite(p.z())) {
        return fail(fmt::format("{}[{}]", field, i), fmt::format("non-finite coordinate ({}, {}, {})", p.x(), p.y(), p.z()));
      }
    }
    return ok_status();
  }

  Status pose(const v1::Pose& value, const std::string& field) const {
    const v1::Vector3& p = value.position();
    const v1::Quaternion& q = value.orientation();
    for (const double component : {p.x(), p.y(), p.z(), q.w(), q.x(), q.y(), q.z()}) {
      HANZO_RETURN_IF_ERROR(finite(component, field));
    }
    const double norm = std::sqrt(q.w() * q.w() + q.x() * q.x() + q.y() * q.y() + q.z() * q.z());
    if (value.has_orientation() && std::abs(norm - 1.0) > 1e-3) {
      return fail(field + ".orientation", fmt::format("quaternion norm {} (expected 1)", norm));
    }
    return ok_status();
  }

  // class_count: the map's label table size (a MapUpdate's points index the map's table).
  Status point_layer(const v1::PointLayer& layer, const std::string& field, uint64_t class_count) const {
    const int count = layer.points_size();
    HANZO_RETURN_IF_ERROR(points(layer.points(), field + ".points"));
    HANZO_RETURN_IF_ERROR(per_element(layer.position_std(), count, field + ".position_std", "points"));
    HANZO_RETURN_IF_ERROR(per_element(layer.labels(), count, field + ".labels", "points"));
    HANZO_RETURN_IF_ERROR(per_element(layer.intensities(), count, field + ".intensities", "points"));
    HANZO_RETURN_IF_ERROR(per_element(layer.classes(), count, field + ".classes", "points"));
    HANZO_RETURN_IF_ERROR(per_element(layer.class_probability(), count, field + ".class_probability", "points"));
    HANZO_RETURN_IF_ERROR(labels(layer.labels(), field + ".labels"));
    HANZO_RETURN_IF_ERROR(classes(layer.classes(), class_count, field + ".classes"));
    for (int i = 0; i < layer.class_probability_size(); ++i) {
      const float probability = layer.class_probability(i);
      if (!(probability >= 0.0F && probability <= 1.0F)) {
        return fail(fmt::format("{}.class_probability[{}]", field, i), fmt::format("{} outside [0, 1]", probability));
      }
    }
    for (int i = 0; i < layer.position_std_size(); ++i) {
      const float sigma = layer.position_std(i);
      if (!std::isfinite(sigma) || sigma < 0.0F) return fail(fmt::format("{}.position_std[{}]", field, i), fmt::format("{} (expected >= 0)", sigma));
    }
    if (!std::isfinite(layer.voxel_size()) || layer.voxel_size() < 0.0) {
      return fail(field + ".voxel_size", fmt::format("{} (expected >= 0)", layer.voxel_size()));
    }
    return ok_status();
  }

  Status occupancy(const v1::OccupancyGridLayer& layer, const std::string& field, uint64_t class_count) const {
    HANZO_RETURN_IF_ERROR(positive(layer.resolution(), field + ".resolution"));
    const uint64_t cells = uint64_t{layer.size_x()} * layer.size_y() * layer.size_z();
    if (static_cast<uint64_t>(layer.occupancy_size()) != cells) {
      return fail(field + ".occupancy", fmt::format("{} cells, but {}x{}x{} needs {}", layer.occupancy_size(), layer.size_x(),
                                                    layer.size_y(), layer.size_z(), cells));
    }
    HANZO_RETURN_IF_ERROR(pose(layer.origin(), field + ".origin"));
    for (int i = 0; i < layer.occupancy_size(); ++i) {
      const float probability = layer.occupancy(i);
      if (!(probability >= 0.0F && probability <= 1.0F)) {
        return fail(fmt::format("{}.occupancy[{}]", field, i), fmt::format("probability {} outside [0, 1]", probability));
      }
    }
    HANZO_RETURN_IF_ERROR(per_element(layer.labels(), layer.occupancy_size(), field + ".labels", "cells"));
    HANZO_RETURN_IF_ERROR(per_element(layer.classes(), layer.occupancy_size(), field + ".classes", "cells"));
    HANZO_RETURN_IF_ERROR(classes(layer.classes(), class_count, field + ".classes"));
    return labels(layer.labels(), field + ".labels");
  }

  Status tsdf(const v1::TsdfLayer& layer, const std::string& field) const {
    HANZO_RETURN_IF_ERROR(positive(layer.voxel_size(), field + ".voxel_size"));
    HANZO_RETURN_IF_ERROR(positive(layer.truncation_distance(), field + ".truncation_distance"));
    if (layer.block_size() == 0 || layer.block_size() > 64) {
      return fail(field + ".block_size", fmt::format("{} (expected 1 to 64 voxels)", layer.block_size()));
    }
    const int voxels = static_cast<int>(layer.block_size() * layer.block_size() * layer.block_size());
    for (int b = 0; b < layer.blocks_size(); ++b) {
      const v1::TsdfBlock& block = layer.blocks(b);
      const std::string block_field = fmt::format("{}.blocks[{}]", field, b);
      if (block.distances_size() != voxels || block.weights_size() != voxels) {
        return fail(block_field, fmt::format("{} distances and {} weights (expected {} each)", block.distances_size(),
                                             block.weights_size(), voxels));
      }
      for (int i = 0; i < voxels; ++i) {
        if (!std::isfinite(block.distances(i))) return fail(fmt::format("{}.distances[{}]", block_field, i), "non-finite value");
        if (!std::isfinite(block.weights(i)) || block.weights(i) < 0.0F) {
          return fail(fmt::format("{}.weights[{}]", block_field, i), fmt::format("{} (expected >= 0)", block.weights(i)));
        }
      }
    }
    return ok_status();
  }

  Status mesh(const v1::MeshLayer& layer, const std::string& field) const {
    HANZO_RETURN_IF_ERROR(points(layer.vertices(), field + ".vertices"));
    if (layer.triangle_indices_size() % 3 != 0) {
      return fail(field + ".triangle_indices", fmt::format("{} indices (expected three per triangle)", layer.triangle_indices_size()));
    }
    for (int i = 0; i < layer.triangle_indices_size(); ++i) {
      if (layer.triangle_indices(i) >= static_cast<uint32_t>(layer.vertices_size())) {
        return fail(fmt::format("{}.triangle_indices[{}]", field, i),
                    fmt::format("index {} past the {} vertices", layer.triangle_indices(i), layer.vertices_size()));
      }
    }
    HANZO_RETURN_IF_ERROR(per_element(layer.vertex_labels(), layer.vertices_size(), field + ".vertex_labels", "vertices"));
    return labels(layer.vertex_labels(), field + ".vertex_labels");
  }

  Status visual_landmarks(const v1::VisualLandmarkLayer& layer, const std::string& field) const {
    HANZO_RETURN_IF_ERROR(points(layer.positions(), field + ".positions"));
    const int count = layer.positions_size();
    if (layer.descriptor_type().empty() || layer.descriptor_type() == "orb") {
      if (layer.descriptors_size() != 4 * count) {
        return fail(field + ".descriptors", fmt::format("{} words for {} landmarks (expected 4 per landmark: 256-bit ORB descriptors)", layer.descriptors_size(), count));
      }
    } else {
      const uint64_t size = layer.float_descriptor_size();
      if (size == 0 || static_cast<uint64_t>(layer.float_descriptors_size()) != size * static_cast<uint64_t>(count) || layer.descriptors_size() != 0) {
        return fail(field + ".float_descriptors", fmt::format("{} floats of size {} for {} landmarks with {} descriptors (expected float_descriptor_size floats per landmark, no binary words)",
                                                              layer.float_descriptors_size(), size, count, layer.descriptor_type()));
      }
      for (int i = 0; i < layer.float_descriptors_size(); ++i) {
        if (!std::isfinite(layer.float_descriptors(i))) return fail(fmt::format("{}.float_descriptors[{}]", field, i), "not finite");
      }
    }
    HANZO_RETURN_IF_ERROR(per_element(layer.position_std(), count, field + ".position_std", "landmarks"));
    HANZO_RETURN_IF_ERROR(per_element(layer.observations(), count, field + ".observations", "landmarks"));
    for (int i = 0; i < layer.position_std_size(); ++i) {
      if (!std::isfinite(layer.position_std(i)) || layer.position_std(i) < 0.0F) {
        return fail(fmt::format("{}.position_std[{}]", field, i), fmt::format("{} (expected a finite value >= 0)", layer.position_std(i)));
      }
    }
    for (int k = 0; k < layer.keyframes_size(); ++k) {
      const v1::VisualKeyframe& keyframe = layer.keyframes(k);
      const std::string keyframe_field = fmt::format("{}.keyframes[{}]", field, k);
      HANZO_RETURN_IF_ERROR(pose(keyframe.pose(), keyframe_field + ".pose"));
      for (int i = 0; i < keyframe.landmarks_size(); ++i) {
        if (keyframe.landmarks(i) >= static_cast<uint32_t>(count)) {
          return fail(fmt::format("{}.landmarks[{}]", keyframe_field, i), fmt::format("index {} past the {} landmarks", keyframe.landmarks(i), count));
        }
      }
    }
    return keyframe_sources(layer, field);
  }

  /// A keyframe layer's sources (non-empty map ids) and each keyframe's index into them.
  template <typename Layer>
  Status keyframe_sources(const Layer& layer, const std::string& field) const {
    for (int i = 0; i < layer.sources_size(); ++i) {
      if (layer.sources(i).empty()) return fail(fmt::format("{}.sources[{}]", field, i), "empty");
    }
    for (int k = 0; k < layer.keyframes_size(); ++k) {
      if (layer.keyframes(k).source() >= static_cast<uint32_t>(std::max(1, layer.sources_size()))) {
        return fail(fmt::format("{}.keyframes[{}].source", field, k), fmt::format("index {} past the {} sources", layer.keyframes(k).source(), layer.sources_size()));
      }
    }
    return ok_status();
  }

  Status lidar_keyframes(const v1::LidarKeyframeLayer& layer, const std::string& field) const {
    for (int k = 0; k < layer.keyframes_size(); ++k) {
      const v1::LidarKeyframe& keyframe = layer.keyframes(k);
      const std::string keyframe_field = fmt::format("{}.keyframes[{}]", field, k);
      HANZO_RETURN_IF_ERROR(pose(keyframe.pose(), keyframe_field + ".pose"));
      HANZO_RETURN_IF_ERROR(points(keyframe.points(), keyframe_field + ".points"));
    }
    return keyframe_sources(layer, field);
  }

  Status gaussian_splats(const v1::GaussianSplatLayer& layer, const std::string& field) const {
    if (layer.sh_degree() > 3) return fail(field + ".sh_degree", fmt::format("{} (expected 0 to 3)", layer.sh_degree()));
    const int64_t count = layer.opacity_logits_size();
    const int64_t sh_floats = 3 * int64_t{layer.sh_degree() + 1} * (layer.sh_degree() + 1);
    struct Group {
      const char* name;
      const google::protobuf::RepeatedField<float>& values;
      int64_t width;  // floats per Gaussian
    };
    const Group groups[] = {{"positions", layer.positions(), 3}, {"log_scales", layer.log_scales(), 3}, {"rotations", layer.rotations(), 4},
                            {"opacity_logits", layer.opacity_logits(), 1}, {"sh", layer.sh(), sh_floats}};
    for (const Group& group : groups) {
      if (group.values.size() != group.width * count) {
        return fail(fmt::format("{}.{}", field, group.name),
                    fmt::format("{} floats for {} Gaussians (expected {} per Gaussian)", group.values.size(), count, group.width));
      }
      for (int i = 0; i < group.values.size(); ++i) {
        if (!std::isfinite(group.values.Get(i))) return fail(fmt::format("{}.{}[{}]", field, group.name, i), "not finite");
      }
    }
    return ok_status();
  }

  Status neural_field(const v1::NeuralFieldLayer& layer, const std::string& field) const {
    if (layer.encoding() != "hznerf1") return fail(field + ".encoding", fmt::format("\"{}\" (this build reads \"hznerf1\")", layer.encoding()));
    std::size_t bytes = 0;
    for (const std::string& part : layer.model_parts()) bytes += part.size();
    if (bytes == 0) return fail(field + ".model_parts", "empty (no model)");
    return ok_status();
  }

 private:
  std::string_view message_name_;
};

}  // namespace

Status validate(const v1::FusionMap& map) {
  const MapChecker check("FusionMap");
  if (map.format_version() != kFusionMapFormatVersion) {
    return check.fail("format_version", fmt::format("unrecognized format version {} (this build reads version {})",
                                                    map.format_version(), kFusionMapFormatVersion));
  }
  if (map.map_id().empty()) return check.fail("map_id", "empty");
  if (map.has_datum()) {
    const Status datum = validate(GeodeticPoint{map.datum().latitude(), map.datum().longitude(), map.datum().altitude()});
    if (!datum) return check.fail("datum", datum.error().message);
  }
  const auto class_count = static_cast<uint64_t>(map.semantic_classes_size());
  for (int i = 0; i < map.semantic_classes_size(); ++i) {
    if (map.semantic_classes(i).empty()) return check.fail(fmt::format("semantic_classes[{}]", i), "empty");
  }
  if (class_count >= kNoClass) return check.fail("semantic_classes", fmt::format("{} classes (at most {})", class_count, kNoClass - 1));
  if (map.has_points()) HANZO_RETURN_IF_ERROR(check.point_layer(map.points(), "points", class_count));
  if (map.has_occupancy()) HANZO_RETURN_IF_ERROR(check.occupancy(map.occupancy(), "occupancy", class_count));
  if (map.has_tsdf()) HANZO_RETURN_IF_ERROR(check.tsdf(map.tsdf(), "tsdf"));
  if (map.has_mesh()) HANZO_RETURN_IF_ERROR(check.mesh(map.mesh(), "mesh"));
  if (map.has_visual_landmarks()) HANZO_RETURN_IF_ERROR(check.visual_landmarks(map.visual_landmarks(), "visual_landmarks"));
  if (map.has_gaussian_splats()) HANZO_RETURN_IF_ERROR(check.gaussian_splats(map.gaussian_splats(), "gaussian_splats"));
  if (map.has_neural_field()) HANZO_RETURN_IF_ERROR(check.neural_field(map.neural_field(), "neural_field"));
  if (map.has_lidar_keyframes()) HANZO_RETURN_IF_ERROR(check.lidar_keyframes(map.lidar_keyframes(), "lidar_keyframes"));
  return ok_status();
}

Status validate(const v1::MapUpdate& update) {
  const MapChecker check("MapUpdate");
  if (update.map_id().empty()) return check.fail("map_id", "empty");
  if (update.timestamp_ns() == 0) return check.fail("timestamp_ns", "zero timestamp (expected nanoseconds since the Unix epoch)");
  if (update.has_added_points()) HANZO_RETURN_IF_ERROR(check.point_layer(update.added_points(), "added_points", kNoClass));
  if (update.has_occupancy_patch()) HANZO_RETURN_IF_ERROR(check.occupancy(update.occupancy_patch(), "occupancy_patch", kNoClass));
  if (update.has_mesh()) HANZO_RETURN_IF_ERROR(check.mesh(update.mesh(), "mesh"));
  return ok_status();
}

}  // namespace hanzo::fusion::msgs
