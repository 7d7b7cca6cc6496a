#pragma once
// Exports of a map's semantic labels (msgs::SemanticLabel: floor, wall, obstacle, traversable,
// unknown; maps/geometric_labels.hpp) for tools that read plain files:
//  - the point layer as a binary little-endian PLY: x y z (float, world metres), red green blue
//    (uchar: the label's colour, semantic_label_color) and label (uchar: the SemanticLabel value),
//    so CloudCompare, MeshLab or Open3D show the classes in colour and can filter on `label`;
//  - the point layer's segmentation classes (PointLayer::classes) as a binary little-endian
//    PLY: x y z, red green blue (semantic_class_color of the class index; grey where no class),
//    class (ushort: the index into FusionMap::semantic_classes, 65535 none) and
//    class_probability (float), with one header comment per class naming it ("class 0 floor");
//  - the 2D occupancy grid as one ROS map_server map per label present (maps/map_export.hpp's
//    PGM + YAML): the label's cells occupied (black), every other cell free (white), so a
//    planner can load "where the floor is" or "where the walls are" as a map of its own.
// Failures: a layer without labels (classes), a 3D grid (label maps are of 2D grids), an
// unwritable path.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

/// The label's colour (red, green, blue): unknown grey, floor steel blue, wall crimson, obstacle
/// orange, traversable green.
std::array<uint8_t, 3> semantic_label_color(msgs::SemanticLabel label);

/// The labelled points' PLY (above); fails for a layer without labels.
Result<std::string> labelled_points_ply(const msgs::PointLayer& layer);
/// Writes labelled_points_ply. Atomic.
Status write_labelled_points_ply(const std::string& path, const msgs::PointLayer& layer);

/// A segmentation class's colour: twelve distinct colours by class index (repeating), grey for
/// msgs::kNoClass.
std::array<uint8_t, 3> semantic_class_color(uint16_t class_index);

/// The points with their segmentation classes (above); class_names is the map's label table.
/// Fails for a layer without classes.
Result<std::string> classified_points_ply(const msgs::PointLayer& layer, const std::vector<std::string>& class_names);
/// Writes classified_points_ply. Atomic.
Status write_classified_points_ply(const std::string& path, const msgs::PointLayer& layer, const std::vector<std::string>& class_names);

/// Writes "<yaml_stem>_<label>.yaml" and its ".pgm" for each label the grid has (above) and
/// returns the files written (YAML, PGM per label, in label order).
Result<std::vector<std::string>> write_label_maps(const std::string& yaml_stem, const msgs::OccupancyGridLayer& layer);

}  // namespace hanzo::fusion::maps
