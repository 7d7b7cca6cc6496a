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

namespace {

// A binary little-endian PLY of coloured points: the header (comments, then x y z, red green
// blue and `extra_properties`), and per point the caller's append_extra after the colour.
template <typename Colour, typename AppendExtra>
std::string coloured_points_ply(const std::vector<Eigen::Vector3f>& points, const std::string& comments, const std::string& extra_properties,
                                std::size_t extra_bytes, const Colour& colour_of, const AppendExtra& append_extra) {
  std::string out = fmt::format("ply\nformat binary_little_endian 1.0\n{}element vertex {}\nproperty float x\nproperty float y\n"
                                "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n{}end_header\n",
                                comments, points.size(), extra_properties);
  out.reserve(out.size() + points.size() * (15 + extra_bytes));
  for (std::size_t i = 0; i < points.size(); ++i) {
    out.append(reinterpret_cast<const char*>(points[i].data()), 3 * sizeof(float));
    const std::array<uint8_t, 3> colour = colour_of(i);
    out.append(reinterpret_cast<const char*>(colour.data()), colour.size());
    append_extra(out, i);  // little-endian hosts (x86-64, aarch64)
  }
  return out;
}

}  // namespace

Result<std::string> labelled_points_ply(const msgs::PointLayer& layer) {
  if (layer.labels.empty()) return Error("point layer: no semantic labels to export (map build labels points by default)", "labels");
  if (layer.labels.size() != layer.points.size()) {
    return Error(fmt::format("point layer: {} labels for {} points", layer.labels.size(), layer.points.size()), "labels");
  }
  return coloured_points_ply(layer.points, "comment hanzo-fusion semantic labels: 0 unknown, 1 floor, 2 wall, 3 obstacle, 4 traversable\n",
                             "property uchar label\n", 1, [&](std::size_t i) { return semantic_label_color(layer.labels[i]); },
                             [&](std::string& out, std::size_t i) { out.push_back(static_cast<char>(layer.labels[i])); });
}

Status write_labelled_points_ply(const std::string& path, const msgs::PointLayer& layer) {
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, labelled_points_ply(layer));
  return yaml::write_file_atomically(path, bytes);
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

Result<std::string> classified_points_ply(const msgs::PointLayer& layer, const std::vector<std::string>& class_names) {
  if (layer.classes.empty()) return Error("point layer: no segmentation classes to export (a session projects a camera segmentation onto its LiDAR map)", "classes");
  if (layer.classes.size() != layer.points.size() || (!layer.class_probability.empty() && layer.class_probability.size() != layer.points.size())) {
    return Error(fmt::format("point layer: {} classes, {} probabilities for {} points", layer.classes.size(), layer.class_probability.size(), layer.points.size()),
                 "classes");
  }
  std::string comments = "comment hanzo-fusion segmentation classes (class 65535: none)\n";
  for (std::size_t i = 0; i < class_names.size(); ++i) comments += fmt::format("comment class {} {}\n", i, class_names[i]);
  return coloured_points_ply(layer.points, comments, "property ushort class\nproperty float class_probability\n", 6,
                             [&](std::size_t i) { return semantic_class_color(layer.classes[i]); },
                             [&](std::string& out, std::size_t i) {
                               out.append(reinterpret_cast<const char*>(&layer.classes[i]), sizeof(uint16_t));
                               const float probability = layer.class_probability.empty() ? 0.0F : layer.class_probability[i];
                               out.append(reinterpret_cast<const char*>(&probability), sizeof(float));
                             });
}

Status write_classified_points_ply(const std::string& path, const msgs::PointLayer& layer, const std::vector<std::string>& class_names) {
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, classified_points_ply(layer, class_names));
  return yaml::write_file_atomically(path, bytes);
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
