#pragma once
// What `hanzo-fusion log info` reports about a sensor log: per channel message counts, rates
// and the largest gap between consecutive messages (a sensor dropout shows up here first).

#include <cstdint>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/mcap.hpp"

namespace hanzo::fusion::io {

struct ChannelSummary {
  uint16_t channel_id = 0;
  std::string topic;
  std::string schema_name;       ///< "" when the channel has no schema
  std::string message_encoding;
  uint64_t message_count = 0;
  uint64_t first_time = 0;       ///< ns
  uint64_t last_time = 0;        ///< ns
  double rate_hz = 0.0;          ///< (count - 1) / (last - first); 0 for fewer than 2 messages
  uint64_t max_gap_ns = 0;       ///< largest time between consecutive messages
  uint64_t max_gap_at = 0;       ///< log time of the message that ends that gap
};

struct LogSummary {
  uint64_t file_size = 0;
  std::string library;
  std::string profile;
  uint64_t message_count = 0;
  uint64_t start_time = 0;  ///< ns
  uint64_t end_time = 0;
  uint32_t chunk_count = 0;
  std::vector<std::string> compressions;  ///< distinct chunk compressions ("none" for uncompressed)
  uint64_t compressed_bytes = 0;          ///< sum over chunks
  uint64_t uncompressed_bytes = 0;
  std::vector<ChannelSummary> channels;   ///< ordered by topic
};

/// Summarizes an opened log. Uses the message indexes when the file has them (no chunk is
/// decompressed); otherwise reads every message once (memory: 8 bytes per message).
Result<LogSummary> summarize_log(const mcap::McapReader& reader);

}  // namespace hanzo::fusion::io
