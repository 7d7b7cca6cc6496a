#pragma once
// Shared by the `map` subcommands: the options of `map build` and the summary of a map that
// `map info`, `map build` and `map import` print.

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "hanzo/fusion/msgs/map_messages.hpp"
#include "output.hpp"

namespace hanzo::fusion::app {

struct MapBuildOptions {
  std::string log;
  std::string trajectory;
  std::string trajectory_format = "tum";
  std::string calibration;
  std::string topic = "/lidar";
  std::string sensor;                        // calibration entry; default: the topic's last component
  std::string occupancy = "2d";              // 2d, 3d or none
  double resolution = 0.05;                  // m
  std::vector<double> height_band{-0.3, 1.0};  // m relative to the sensor
  double points_voxel = 0.1;                 // m, 0: no point layer
  double max_range = 0.0;                    // m, 0: no limit
  double tsdf_voxel = 0.0;                   // m, 0: no TSDF / mesh
  bool keep_moving_points = false;           // true: points other scans saw through stay in the point layer
  std::string map_id;
  std::string frame = "world";
  std::string out;
};

int run_map_build(const Output& output, const MapBuildOptions& options);

/// Metadata and per-layer summary (counts, extents, occupied / free / unknown cells).
nlohmann::json describe_map(const msgs::FusionMap& map);
/// The layer lines of describe_map's JSON as text.
std::string describe_map_text(const nlohmann::json& description);

}  // namespace hanzo::fusion::app
