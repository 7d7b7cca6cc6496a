#pragma once
// Writing a sensor log from a subcommand (import, sim): the log appears at its path only when
// complete, so a failure never leaves a half-written log behind.

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include <nlohmann/json.hpp>

#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/privacy/log_redaction.hpp"
#include "output.hpp"

namespace hanzo::fusion::app {

/// The privacy filter applied to every image before it is written, and what it found.
struct ImageRedaction {
  std::shared_ptr<privacy::PrivacyFilter> filter;
  privacy::TopicRedactionCounts counts;
};

struct LogWriteOptions {
  std::string path;                  ///< the .mcap to write
  std::string compression = "zstd";  ///< zstd, lz4 or none
  bool foxglove_channels = true;     ///< Foxglove mirror channels
  std::string image_compression = "none";  ///< none, png or jpeg
  int jpeg_quality = 90;
  double point_resolution = 0.0;     ///< m; 0: exact point coordinates
  /// When set, images are redacted before they are written; the counts go to result["privacy"].
  std::shared_ptr<ImageRedaction> redaction;
};

/// Opens PATH.partial, lets `fill` write it, and renames it into place when complete. Returns 0,
/// or reports the failure (with `result`) and returns its exit code.
int write_log(const Output& output, nlohmann::json& result, const LogWriteOptions& options,
              const std::function<Status(io::SensorLogWriter&)>& fill);

}  // namespace hanzo::fusion::app
