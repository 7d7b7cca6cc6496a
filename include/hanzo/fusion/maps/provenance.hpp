#pragma once
// Provenance records of the FusionMap: which input files a map was built from, identified by
// their SHA-256 digest so that a map can be traced to the exact data (and a changed file
// noticed).

#include <string>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

/// Lower-case hex SHA-256 of a file's bytes (read in 1 MiB pieces).
Result<std::string> sha256_of_file(const std::string& path);

/// {uri: "file://<absolute path>", sha256: digest}.
Result<msgs::InputLog> describe_input_file(const std::string& path);

}  // namespace hanzo::fusion::maps
