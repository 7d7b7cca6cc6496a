#pragma once
// Map exports and imports in the formats other tools read:
//
//  - ROS map_server maps: a PGM image plus a YAML file (image, resolution, origin [x, y, yaw],
//    negate, occupied_thresh, free_thresh, mode). Written like map_saver does in "trinary"
//    mode: occupied 0 (black), free 254 (white), unknown 205 (grey); the image's first row is
//    the grid's last y row (image up = world +y). Read in trinary, scale or raw mode.
//  - PNG pictures: the occupancy grid in grey levels (probability of occupancy: black
//    occupied, white free, mid grey unknown; 3D grids are flattened, a column being as occupied
//    as its most occupied cell), and a top-down view of a point layer coloured by height.
//  - Point layers as PCD / PLY / KITTI .bin (cloud/cloud_io.hpp) and back; meshes as PLY / OBJ.
//
// 3D occupancy grids export to PGM flattened like the PNG.

#include <string>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

struct RosMapConfig {
  double occupied_threshold = 0.65;  ///< occupied_thresh
  double free_threshold = 0.196;     ///< free_thresh
};

/// A 2D layer from any layer: size_z == 1 layers unchanged; 3D ones flattened by the maximum
/// probability of each column over observed cells (unknown where no cell of the column is
/// observed).
msgs::OccupancyGridLayer flatten_occupancy(const msgs::OccupancyGridLayer& layer);

/// Writes `yaml_path` and the PGM next to it (same name, ".pgm"), atomically each.
Status write_ros_map(const std::string& yaml_path, const msgs::OccupancyGridLayer& layer, const RosMapConfig& config = {});
/// Reads a map_server YAML and its image (path relative to the YAML). A pixel's probability is
/// (255 - value) / 255 (value / 255 with negate: 1). Trinary mode keeps it for cells above
/// occupied_thresh or below free_thresh and makes the rest unknown (0.5); scale mode keeps it
/// for every cell; raw mode reads values 0..100 as percent and others as unknown.
Result<msgs::OccupancyGridLayer> read_ros_map(const std::string& yaml_path);

/// Grey-level PNG of the (flattened) occupancy grid, one pixel per cell, north up.
Status write_occupancy_png(const std::string& path, const msgs::OccupancyGridLayer& layer);
/// Top-down PNG of the points coloured by height (turbo colour map, low blue, high red) on
/// white; `pixel_size` in meters (0: chosen so the longer side has about 1600 pixels).
Status write_points_png(const std::string& path, const msgs::PointLayer& layer, double pixel_size = 0.0);

/// Writes a mesh layer by extension: ".ply" (binary little-endian, vertices as float x y z,
/// faces as uchar-counted int lists, readable by MeshLab, Open3D, Blender) or ".obj" (text).
/// Atomic.
Status write_mesh(const std::string& path, const msgs::MeshLayer& mesh);

/// Point layer <-> point cloud (positions and intensities).
cloud::PointCloud to_point_cloud(const msgs::PointLayer& layer);
msgs::PointLayer to_point_layer(const cloud::PointCloud& cloud, double voxel_size = 0.0);

}  // namespace hanzo::fusion::maps
