#pragma once
// Redacting a sensor log (io/sensor_log.hpp): every camera image passes the PrivacyFilter,
// every other message, the channels' sensor names and the log's metadata records are copied;
// the Foxglove mirror channels are written again (from the redacted images) when the input had
// them, whatever writer_config.foxglove_channels says.
// The output is written to `<output>.partial` and renamed when complete: a failure (a message
// that does not decode, a full disk) leaves no output file, and the input is never touched.

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/privacy/privacy_filter.hpp"

namespace hanzo::fusion::privacy {

struct TopicRedactionCounts {
  uint64_t images = 0;
  uint64_t redacted_images = 0;  ///< images with at least one region
  uint64_t faces = 0;
  uint64_t licence_plates = 0;
};

/// Adds one image and the regions found in it to `counts`.
void count_regions(const std::vector<RedactedRegion>& regions, TopicRedactionCounts& counts);

struct LogRedactionSummary {
  uint64_t messages = 0;
  TopicRedactionCounts total;
  std::map<std::string, TopicRedactionCounts> by_topic;  ///< camera topics only
  /// The reader's warning when the input had no summary or was cut off (what was recovered is
  /// redacted and written).
  std::optional<std::string> input_warning;
};

Result<LogRedactionSummary> redact_log(PrivacyFilter& filter, const std::string& input_path, const std::string& output_path,
                                       const io::SensorLogWriterConfig& writer_config);

}  // namespace hanzo::fusion::privacy
