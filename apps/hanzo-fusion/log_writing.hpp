#pragma once
// Writing a sensor log from a subcommand (import, sim): the log appears at its path only when
// complete, so a failure never leaves a half-written log behind.

#include <functional>
#include <string>

#include <nlohmann/json.hpp>

#include "hanzo/fusion/io/sensor_log.hpp"
#include "output.hpp"

namespace hanzo::fusion::app {

struct LogWriteOptions {
  std::string path;                  ///< the .mcap to write
  std::string compression = "zstd";  ///< zstd, lz4 or none
  bool foxglove_channels = true;     ///< Foxglove mirror channels
  std::string image_compression = "none";  ///< none, png or jpeg
  int jpeg_quality = 90;
  double point_resolution = 0.0;     ///< m; 0: exact point coordinates
};

/// Opens PATH.partial, lets `fill` write it, and renames it into place when complete. Returns 0,
/// or reports the failure (with `result`) and returns its exit code.
int write_log(const Output& output, nlohmann::json& result, const LogWriteOptions& options,
              const std::function<Status(io::SensorLogWriter&)>& fill);

}  // namespace hanzo::fusion::app
