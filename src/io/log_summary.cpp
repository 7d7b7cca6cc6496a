#include "hanzo/fusion/io/log_summary.hpp"

#include <algorithm>
#include <map>

#include <fmt/format.h>

#include "mcap_format.hpp"

namespace hanzo::fusion::io {

namespace {

// Log times per channel from the Message Index records that follow each chunk; nullopt when
// the file has no indexes for some chunk.
Result<std::optional<std::map<uint16_t, std::vector<uint64_t>>>> times_from_indexes(const mcap::McapReader& reader) {
  std::map<uint16_t, std::vector<uint64_t>> times;
  if (reader.chunk_indexes().empty() || reader.warning()) return std::optional<std::map<uint16_t, std::vector<uint64_t>>>();
  for (const mcap::ChunkIndex& chunk : reader.chunk_indexes()) {
    if (chunk.message_index_offsets.empty() && chunk.message_start_time != 0) {
      return std::optional<std::map<uint16_t, std::vector<uint64_t>>>();
    }
    if (chunk.message_index_length == 0) continue;
    const uint64_t start = chunk.chunk_start_offset + chunk.chunk_length;
    std::string bytes;
    HANZO_ASSIGN_OR_RETURN(bytes, reader.read_range(start, chunk.message_index_length));
    mcap::format::ByteReader r(bytes);
    while (r.remaining() > 0) {
      const uint8_t opcode = r.u8();
      mcap::format::ByteReader content(r.bytes(r.u64()));
      if (!r.ok()) return Error(fmt::format("malformed message index after the chunk at byte {}", chunk.chunk_start_offset));
      if (opcode != mcap::format::kMessageIndex) continue;
      std::vector<uint64_t>& channel_times = times[content.u16()];
      mcap::format::ByteReader entries(content.string());
      while (entries.remaining() >= 16) {
        channel_times.push_back(entries.u64());
        entries.u64();
      }
      if (!content.ok()) return Error(fmt::format("malformed message index after the chunk at byte {}", chunk.chunk_start_offset));
    }
  }
  return std::optional<std::map<uint16_t, std::vector<uint64_t>>>(std::move(times));
}

}  // namespace

Result<LogSummary> summarize_log(const mcap::McapReader& reader) {
  LogSummary summary;
  summary.file_size = reader.file_size();
  summary.library = reader.library();
  summary.profile = reader.profile();
  summary.chunk_count = static_cast<uint32_t>(reader.chunk_indexes().size());
  for (const mcap::ChunkIndex& chunk : reader.chunk_indexes()) {
    const std::string name = chunk.compression.empty() ? "none" : chunk.compression;
    if (std::find(summary.compressions.begin(), summary.compressions.end(), name) == summary.compressions.end()) {
      summary.compressions.push_back(name);
    }
    summary.compressed_bytes += chunk.compressed_size;
    summary.uncompressed_bytes += chunk.uncompressed_size;
  }

  std::optional<std::map<uint16_t, std::vector<uint64_t>>> indexed;
  HANZO_ASSIGN_OR_RETURN(indexed, times_from_indexes(reader));
  std::map<uint16_t, std::vector<uint64_t>> times;
  if (indexed) {
    times = std::move(*indexed);
  } else {
    mcap::MessageIterator it = reader.messages();
    mcap::MessageView view;
    while (true) {
      bool more = false;
      HANZO_ASSIGN_OR_RETURN(more, it.next(view));
      if (!more) break;
      times[view.channel->id].push_back(view.log_time);
    }
  }
  for (const auto& [id, channel] : reader.channels()) {
    ChannelSummary c;
    c.channel_id = id;
    c.topic = channel.topic;
    c.message_encoding = channel.message_encoding;
    const auto schema = reader.schemas().find(channel.schema_id);
    if (schema != reader.schemas().end()) c.schema_name = schema->second.name;
    std::vector<uint64_t>& t = times[id];
    std::sort(t.begin(), t.end());
    c.message_count = t.size();
    if (!t.empty()) {
      c.first_time = t.front();
      c.last_time = t.back();
      if (summary.message_count == 0 || c.first_time < summary.start_time) summary.start_time = c.first_time;
      summary.end_time = std::max(summary.end_time, c.last_time);
    }
    for (std::size_t i = 1; i < t.size(); ++i) {
      if (t[i] - t[i - 1] > c.max_gap_ns) {
        c.max_gap_ns = t[i] - t[i - 1];
        c.max_gap_at = t[i];
      }
    }
    if (t.size() >= 2 && c.last_time > c.first_time) {
      c.rate_hz = static_cast<double>(t.size() - 1) / (static_cast<double>(c.last_time - c.first_time) * 1e-9);
    }
    summary.message_count += c.message_count;
    summary.channels.push_back(std::move(c));
  }
  std::sort(summary.channels.begin(), summary.channels.end(),
            [](const ChannelSummary& a, const ChannelSummary& b) { return a.topic < b.topic; });
  return summary;
}

}  // namespace hanzo::fusion::io
