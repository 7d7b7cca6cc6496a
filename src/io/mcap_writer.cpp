#include <algorithm>
#include <cerrno>
#include <cstring>

#include <fmt/format.h>
#include <unistd.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/io/mcap.hpp"
#include "mcap_compression.hpp"
#include "mcap_format.hpp"

namespace hanzo::fusion::io::mcap {

using format::ByteWriter;

namespace {

std::string schema_record(const Schema& schema) {
  std::string content;
  ByteWriter w(content);
  w.u16(schema.id);
  w.string(schema.name);
  w.string(schema.encoding);
  w.bytes32(schema.data);
  return format::record(format::kSchema, content);
}

std::string channel_record(const Channel& channel) {
  std::string content;
  ByteWriter w(content);
  w.u16(channel.id);
  w.u16(channel.schema_id);
  w.string(channel.topic);
  w.string(channel.message_encoding);
  w.string_map(channel.metadata);
  return format::record(format::kChannel, content);
}

}  // namespace

Result<std::unique_ptr<McapWriter>> McapWriter::open(const std::string& path, const McapWriterConfig& config) {
  if (config.chunk_size == 0) return Error("MCAP writer: chunk_size must be positive");
  std::unique_ptr<McapWriter> writer(new McapWriter());
  writer->config_ = config;
  writer->path_ = path;
  writer->file_ = std::fopen(path.c_str(), "wb");
  if (writer->file_ == nullptr) return Error(fmt::format("{}: cannot create file ({})", path, std::strerror(errno)));
  std::setvbuf(writer->file_, nullptr, _IOFBF, 1u << 20);
  std::string header;
  ByteWriter w(header);
  w.string(config.profile);
  w.string(config.library);
  HANZO_RETURN_IF_ERROR(writer->write_bytes(std::string_view(format::kMagic, format::kMagicSize)));
  HANZO_RETURN_IF_ERROR(writer->write_bytes(format::record(format::kHeader, header)));
  return writer;
}

McapWriter::~McapWriter() {
  if (!closed_ && file_ != nullptr) {
    if (Status status = close(); !status) logger()->error("{}", status.error().message);
  }
}

Status McapWriter::write_bytes(std::string_view bytes) {
  if (std::fwrite(bytes.data(), 1, bytes.size(), file_) != bytes.size()) {
    return Error(fmt::format("{}: write failed at byte {} ({})", path_, file_offset_, std::strerror(errno)));
  }
  data_crc_ = format::crc32_update(data_crc_, bytes);
  file_offset_ += bytes.size();
  return ok_status();
}

Result<uint16_t> McapWriter::add_schema(const std::string& name, const std::string& encoding, const std::string& data) {
  if (closed_) return Error(fmt::format("{}: writer is closed", path_));
  for (const Schema& schema : schemas_) {
    if (schema.name == name && schema.encoding == encoding && schema.data == data) return schema.id;
  }
  if (schemas_.size() >= UINT16_MAX) return Error("MCAP writer: too many schemas (65535)");
  schemas_.push_back({static_cast<uint16_t>(schemas_.size() + 1), name, encoding, data});
  return schemas_.back().id;
}

Result<uint16_t> McapWriter::add_channel(uint16_t schema_id, const std::string& topic, const std::string& message_encoding,
                                         const std::map<std::string, std::string>& metadata) {
  if (closed_) return Error(fmt::format("{}: writer is closed", path_));
  if (schema_id > schemas_.size()) return Error(fmt::format("MCAP writer: channel '{}' refers to unknown schema {}", topic, schema_id));
  for (const Channel& channel : channels_) {
    if (channel.topic != topic) continue;
    if (channel.schema_id == schema_id && channel.message_encoding == message_encoding && channel.metadata == metadata) {
      return channel.id;
    }
    return Error(fmt::format("MCAP writer: topic '{}' is already registered with another schema or encoding", topic));
  }
  if (channels_.size() >= UINT16_MAX) return Error("MCAP writer: too many channels (65535)");
  // Channel ids start at 0 as in the reference writers; 0 is a valid channel id.
  channels_.push_back({static_cast<uint16_t>(channels_.size()), schema_id, topic, message_encoding, metadata});
  return channels_.back().id;
}

Status McapWriter::write(uint16_t channel_id, uint64_t log_time, uint64_t publish_time, std::string_view data,
                         uint32_t sequence) {
  if (closed_) return Error(fmt::format("{}: writer is closed", path_));
  if (channel_id >= channels_.size()) return Error(fmt::format("MCAP writer: unknown channel {}", channel_id));
  const Channel& channel = channels_[channel_id];
  // Each chunk defines the schemas and channels its messages use, so it can be read alone.
  if (chunk_channels_.insert(channel_id).second) {
    if (channel.schema_id != 0 && chunk_schemas_.insert(channel.schema_id).second) {
      chunk_records_ += schema_record(schemas_[channel.schema_id - 1]);
    }
    chunk_records_ += channel_record(channel);
  }
  if (sequence == 0) sequence = ++sequence_counters_[channel_id];
  const uint64_t offset_in_chunk = chunk_records_.size();
  ByteWriter w(chunk_records_);
  w.u8(format::kMessage);
  w.u64(2 + 4 + 8 + 8 + data.size());
  w.u16(channel_id);
  w.u32(sequence);
  w.u64(log_time);
  w.u64(publish_time);
  w.raw(data);
  chunk_message_index_[channel_id].emplace_back(log_time, offset_in_chunk);
  chunk_start_time_ = std::min(chunk_start_time_, log_time);
  chunk_end_time_ = std::max(chunk_end_time_, log_time);

  if (statistics_.message_count == 0 || log_time < statistics_.message_start_time) statistics_.message_start_time = log_time;
  statistics_.message_end_time = std::max(statistics_.message_end_time, log_time);
  ++statistics_.message_count;
  ++statistics_.channel_message_counts[channel_id];
  if (chunk_records_.size() >= config_.chunk_size) return flush_chunk();
  return ok_status();
}

Status McapWriter::flush_chunk() {
  if (chunk_records_.empty()) return ok_status();
  std::string compressed;
  HANZO_ASSIGN_OR_RETURN(compressed, compress(config_.compression, config_.compression_level, chunk_records_));
  ChunkIndex index;
  index.message_start_time = chunk_message_index_.empty() ? 0 : chunk_start_time_;
  index.message_end_time = chunk_message_index_.empty() ? 0 : chunk_end_time_;
  index.chunk_start_offset = file_offset_;
  index.compression = compression_name(config_.compression);
  index.compressed_size = compressed.size();
  index.uncompressed_size = chunk_records_.size();

  std::string content;
  ByteWriter w(content);
  w.u64(index.message_start_time);
  w.u64(index.message_end_time);
  w.u64(chunk_records_.size());
  w.u32(format::crc32_of(chunk_records_));
  w.string(index.compression);
  w.u64(compressed.size());
  // Write the header part and the compressed bytes separately (no copy of the payload).
  std::string prefix;
  ByteWriter p(prefix);
  p.u8(format::kChunk);
  p.u64(content.size() + compressed.size());
  HANZO_RETURN_IF_ERROR(write_bytes(prefix));
  HANZO_RETURN_IF_ERROR(write_bytes(content));
  HANZO_RETURN_IF_ERROR(write_bytes(compressed));
  index.chunk_length = file_offset_ - index.chunk_start_offset;

  const uint64_t message_index_start = file_offset_;
  for (const auto& [channel_id, entries] : chunk_message_index_) {
    std::string body;
    ByteWriter m(body);
    m.u16(channel_id);
    m.u32(static_cast<uint32_t>(entries.size() * 16));
    for (const auto& [time, offset] : entries) {
      m.u64(time);
      m.u64(offset);
    }
    index.message_index_offsets[channel_id] = file_offset_;
    HANZO_RETURN_IF_ERROR(write_bytes(format::record(format::kMessageIndex, body)));
  }
  index.message_index_length = file_offset_ - message_index_start;
  chunk_indexes_.push_back(std::move(index));
  ++statistics_.chunk_count;

  chunk_records_.clear();
  chunk_message_index_.clear();
  chunk_schemas_.clear();
  chunk_channels_.clear();
  chunk_start_time_ = UINT64_MAX;
  chunk_end_time_ = 0;
  return ok_status();
}

Status McapWriter::add_metadata(const Metadata& metadata) {
  if (closed_) return Error(fmt::format("{}: writer is closed", path_));
  // Metadata records live in the data section outside chunks: close the open chunk first so
  // the records stay in file order.
  HANZO_RETURN_IF_ERROR(flush_chunk());
  std::string content;
  ByteWriter w(content);
  w.string(metadata.name);
  w.string_map(metadata.values);
  const uint64_t offset = file_offset_;
  HANZO_RETURN_IF_ERROR(write_bytes(format::record(format::kMetadata, content)));
  metadata_index_.emplace_back(offset, file_offset_ - offset);
  metadata_names_.push_back(metadata.name);
  ++statistics_.metadata_count;
  return ok_status();
}

Status McapWriter::close() {
  if (closed_) return ok_status();
  closed_ = true;
  auto finish = [this]() -> Status {
    HANZO_RETURN_IF_ERROR(flush_chunk());
    std::string data_end;
    ByteWriter(data_end).u32(data_crc_);  // CRC of every byte from the leading magic to here
    HANZO_RETURN_IF_ERROR(write_bytes(format::record(format::kDataEnd, data_end)));

    // Summary section: one group per record type, each remembered for the Summary Offsets.
    const uint64_t summary_start = file_offset_;
    data_crc_ = 0;  // from here on the running CRC is the summary CRC
    std::vector<std::pair<uint8_t, std::pair<uint64_t, uint64_t>>> groups;
    auto write_group = [&](uint8_t opcode, const std::vector<std::string>& records) -> Status {
      if (records.empty()) return ok_status();
      const uint64_t start = file_offset_;
      for (const std::string& r : records) HANZO_RETURN_IF_ERROR(write_bytes(r));
      groups.push_back({opcode, {start, file_offset_ - start}});
      return ok_status();
    };
    std::vector<std::string> records;
    for (const Schema& schema : schemas_) records.push_back(schema_record(schema));
    HANZO_RETURN_IF_ERROR(write_group(format::kSchema, records));
    records.clear();
    for (const Channel& channel : channels_) records.push_back(channel_record(channel));
    HANZO_RETURN_IF_ERROR(write_group(format::kChannel, records));

    statistics_.schema_count = static_cast<uint16_t>(schemas_.size());
    statistics_.channel_count = static_cast<uint32_t>(channels_.size());
    std::string stats;
    ByteWriter s(stats);
    s.u64(statistics_.message_count);
    s.u16(statistics_.schema_count);
    s.u32(statistics_.channel_count);
    s.u32(statistics_.attachment_count);
    s.u32(statistics_.metadata_count);
    s.u32(statistics_.chunk_count);
    s.u64(statistics_.message_start_time);
    s.u64(statistics_.message_end_time);
    s.id_count_map(statistics_.channel_message_counts);
    HANZO_RETURN_IF_ERROR(write_group(format::kStatistics, {format::record(format::kStatistics, stats)}));

    records.clear();
    for (const ChunkIndex& index : chunk_indexes_) {
      std::string body;
      ByteWriter c(body);
      c.u64(index.message_start_time);
      c.u64(index.message_end_time);
      c.u64(index.chunk_start_offset);
      c.u64(index.chunk_length);
      c.id_count_map(index.message_index_offsets);
      c.u64(index.message_index_length);
      c.string(index.compression);
      c.u64(index.compressed_size);
      c.u64(index.uncompressed_size);
      records.push_back(format::record(format::kChunkIndex, body));
    }
    HANZO_RETURN_IF_ERROR(write_group(format::kChunkIndex, records));
    records.clear();
    for (std::size_t i = 0; i < metadata_index_.size(); ++i) {
      std::string body;
      ByteWriter m(body);
      m.u64(metadata_index_[i].first);
      m.u64(metadata_index_[i].second);
      m.string(metadata_names_[i]);
      records.push_back(format::record(format::kMetadataIndex, body));
    }
    HANZO_RETURN_IF_ERROR(write_group(format::kMetadataIndex, records));

    const uint64_t summary_offset_start = file_offset_;
    for (const auto& [opcode, range] : groups) {
      std::string body;
      ByteWriter o(body);
      o.u8(opcode);
      o.u64(range.first);
      o.u64(range.second);
      HANZO_RETURN_IF_ERROR(write_bytes(format::record(format::kSummaryOffset, body)));
    }
    // Footer: its CRC covers the summary, the summary offsets and the footer up to the CRC.
    std::string footer;
    ByteWriter f(footer);
    f.u8(format::kFooter);
    f.u64(format::kFooterContentSize);
    f.u64(summary_start);
    f.u64(summary_offset_start);
    HANZO_RETURN_IF_ERROR(write_bytes(footer));
    std::string crc;
    ByteWriter(crc).u32(data_crc_);
    HANZO_RETURN_IF_ERROR(write_bytes(crc));
    HANZO_RETURN_IF_ERROR(write_bytes(std::string_view(format::kMagic, format::kMagicSize)));
    if (std::fflush(file_) != 0 || ::fsync(::fileno(file_)) != 0) {
      return Error(fmt::format("{}: cannot flush to disk ({})", path_, std::strerror(errno)));
    }
    return ok_status();
  };
  Status status = finish();
  if (std::fclose(file_) != 0 && status) status = Error(fmt::format("{}: close failed ({})", path_, std::strerror(errno)));
  file_ = nullptr;
  return status;
}

}  // namespace hanzo::fusion::io::mcap
