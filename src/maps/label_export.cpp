#include "hanzo/fusion/maps/label_export.hpp"

#include <filesystem>
#include <set>

#include <fmt/format.h>

#include "hanzo/fusion/core/yaml_value.hpp"
#include "hanzo/fusion/maps/geometric_labels.hpp"
#include "hanzo/fusion/maps/map_export.hpp"

namespace hanzo::fusion::maps {

std::array<uint8_t, 3> semantic_label_color(msgs::SemanticLabel label) {
  switch (label) {
    case msgs::SemanticLabel::kFloor: return {70, 130, 180};
    case msgs::SemanticLabel::kWall: return {220, 20, 60};
    case msgs::SemanticLabel::kObstacle: return {255, 165, 0};
    case msgs::SemanticLabel::kTraversable: return {60, 179, 113};
    case msgs::SemanticLabel::kUnknown: break;
  }
  return {128, 128, 128};
}

Status write_labelled_points_ply(const std::string& path, const msgs::PointLayer& layer) {
  if (layer.labels.empty()) return Error("point layer: no semantic labels to export (map build labels points by default)", "labels");
  if (layer.labels.size() != layer.points.size()) {
    return Error(fmt::format("point layer: {} labels for {} points", layer.labels.size(), layer.points.size()), "labels");
  }
  std::string out = fmt::format("ply\nformat binary_little_endian 1.0\ncomment hanzo-fusion semantic labels: 0 unknown, 1 floor, 2 wall, "
                                "3 obstacle, 4 traversable\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\n"
                                "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar label\nend_header\n",
                                layer.points.size());
  out.reserve(out.size() + layer.points.size() * 16);
  for (std::size_t i = 0; i < layer.points.size(); ++i) {
    out.append(reinterpret_cast<const char*>(layer.points[i].data()), 3 * sizeof(float));
    const std::array<uint8_t, 3> color = semantic_label_color(layer.labels[i]);
    out.append(reinterpret_cast<const char*>(color.data()), color.size());
    out.push_back(static_cast<char>(layer.labels[i]));
  }
  return yaml::write_file_atomically(path, out);
}

std::array<uint8_t, 3> semantic_class_color(uint16_t class_index) {
  static constexpr std::array<std::array<uint8_t, 3>, 12> kPalette{{{31, 119, 180},
                                                                     {255, 127, 14},
                                                                     {44, 160, 44},
                                                                     {214, 39, 40},
                                                                     {148, 103, 189},
                                                                     {140, 86, 75},
                                                                     {227, 119, 194},
                                                                     {188, 189, 34},
                                                                     {23, 190, 207},
                                                                     {174, 199, 232},
                                                                     {255, 187, 120},
                                                                     {152, 223, 138}}};
  if (class_index == msgs::kNoClass) return {128, 128, 128};
  return kPalette[class_index % kPalette.size()];
}

Status write_classified_points_ply(const std::string& path, const msgs::PointLayer& layer, const std::vector<std::string>& class_names) {
  if (layer.classes.empty()) return Error("point layer: no segmentation classes to export (a session projects a camera segmentation onto its LiDAR map)", "classes");
  if (layer.classes.size() != layer.points.size() || (!layer.class_probability.empty() && layer.class_probability.size() != layer.points.size())) {
    return Error(fmt::format("point layer: {} classes, {} probabilities for {} points", layer.classes.size(), layer.class_probability.size(), layer.points.size()),
                 "classes");
  }
  std::string out = "ply\nformat binary_little_endian 1.0\ncomment hanzo-fusion segmentation classes (class 65535: none)\n";
  for (std::size_t i = 0; i < class_names.size(); ++i) out += fmt::format("comment class {} {}\n", i, class_names[i]);
  out += fmt::format("element vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
                     "property uchar blue\nproperty ushort class\nproperty float class_probability\nend_header\n",
                     layer.points.size());
  out.reserve(out.size() + layer.points.size() * 21);
  for (std::size_t i = 0; i < layer.points.size(); ++i) {
    out.append(reinterpret_cast<const char*>(layer.points[i].data()), 3 * sizeof(float));
    const std::array<uint8_t, 3> color = semantic_class_color(layer.classes[i]);
    out.append(reinterpret_cast<const char*>(color.data()), color.size());
    out.append(reinterpret_cast<const char*>(&layer.classes[i]), sizeof(uint16_t));  // little-endian hosts (x86-64, aarch64)
    const float probability = layer.class_probability.empty() ? 0.0F : layer.class_probability[i];
    out.append(reinterpret_cast<const char*>(&probability), sizeof(float));
  }
  return yaml::write_file_atomically(path, out);
}

Result<std::vector<std::string>> write_label_maps(const std::string& yaml_stem, const msgs::OccupancyGridLayer& layer) {
  if (layer.labels.empty()) return Error("occupancy grid: no semantic labels to export (map build labels 2D grids by default)", "labels");
  if (layer.size_z != 1) return Error(fmt::format("occupancy grid: {} layers high; label maps are of 2D grids", layer.size_z), "size_z");
  if (layer.labels.size() != layer.occupancy.size()) {
    return Error(fmt::format("occupancy grid: {} labels for {} cells", layer.labels.size(), layer.occupancy.size()), "labels");
  }
  const std::set<msgs::SemanticLabel> present(layer.labels.begin(), layer.labels.end());
  std::vector<std::string> files;
  for (const msgs::SemanticLabel label : present) {
    msgs::OccupancyGridLayer map = layer;
    map.labels.clear();
    for (std::size_t i = 0; i < map.occupancy.size(); ++i) map.occupancy[i] = layer.labels[i] == label ? 1.0F : 0.0F;
    const std::string yaml = fmt::format("{}_{}.yaml", yaml_stem, semantic_label_name(label));
    HANZO_RETURN_IF_ERROR(write_ros_map(yaml, map));
    files.push_back(yaml);
    files.push_back(std::filesystem::path(yaml).replace_extension(".pgm").string());
  }
  return files;
}

}  // namespace hanzo::fusion::maps
