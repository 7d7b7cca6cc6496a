// Fuzz target: the text and file formats users hand the program: the fusion configuration and
// calibration (YAML), trajectories (TUM, KITTI, EuRoC), pose graphs (g2o / TORO), sensor CSV
// files and FusionMap files. The first byte picks the format; the rest is the file. Any input
// must be parsed or refused with an error naming the problem, never crash.

#include <cstddef>
#include <cstdint>
#include <string>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/graph/g2o_io.hpp"
#include "hanzo/fusion/io/csv_import.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion;
  if (size == 0) return 0;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  switch (data[0] % 8) {
    case 0: (void)config::parse_fusion_config(text, "fuzz"); break;
    case 1: (void)calib::parse_calibration(text, "fuzz"); break;
    case 2: (void)io::parse_trajectory(text, io::TrajectoryFormat::kTum, "fuzz"); break;
    case 3: (void)io::parse_trajectory(text, io::TrajectoryFormat::kKitti, "fuzz"); break;
    case 4: (void)io::parse_trajectory(text, io::TrajectoryFormat::kEuroc, "fuzz"); break;
    case 5: (void)graph::parse_g2o(text, "fuzz"); break;
    case 6: (void)io::parse_sensor_csv(text, "fuzz"); break;
    default: (void)maps::parse_fusion_map(text, "fuzz"); break;
  }
  return 0;
}
