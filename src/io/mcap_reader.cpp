#include <algorithm>
#include <cerrno>
#include <cstring>
#include <queue>

#include <fcntl.h>
#include <fmt/format.h>
#include <sys/stat.h>
#include <unistd.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/io/mcap.hpp"
#include "mcap_compression.hpp"
#include "mcap_format.hpp"

namespace hanzo::fusion::io::mcap {

using format::ByteReader;

namespace {

struct RecordView {
  uint8_t opcode = 0;
  std::string_view content;
};

// The next record of `reader` or nullopt when the bytes end inside it.
std::optional<RecordView> next_record(ByteReader& reader) {
  RecordView record;
  record.opcode = reader.u8();
  const uint64_t length = reader.u64();
  if (!reader.ok()) return std::nullopt;
  record.content = reader.bytes(length);
  if (!reader.ok()) return std::nullopt;
  return record;
}

std::optional<Schema> parse_schema(std::string_view content) {
  ByteReader r(content);
  Schema schema;
  schema.id = r.u16();
  schema.name = r.string();
  schema.encoding = r.string();
  schema.data = r.string();
  return r.ok() ? std::optional<Schema>(std::move(schema)) : std::nullopt;
}

std::optional<Channel> parse_channel(std::string_view content) {
  ByteReader r(content);
  Channel channel;
  channel.id = r.u16();
  channel.schema_id = r.u16();
  channel.topic = r.string();
  channel.message_encoding = r.string();
  channel.metadata = r.string_map();
  return r.ok() ? std::optional<Channel>(std::move(channel)) : std::nullopt;
}

std::optional<Metadata> parse_metadata(std::string_view content) {
  ByteReader r(content);
  Metadata metadata;
  metadata.name = r.string();
  metadata.values = r.string_map();
  return r.ok() ? std::optional<Metadata>(std::move(metadata)) : std::nullopt;
}

struct ChunkHeader {
  uint64_t start_time = 0;
  uint64_t end_time = 0;
  uint64_t uncompressed_size = 0;
  uint32_t uncompressed_crc = 0;
  std::string_view compression;
  std::string_view compressed;
};

std::optional<ChunkHeader> parse_chunk(std::string_view content) {
  ByteReader r(content);
  ChunkHeader chunk;
  chunk.start_time = r.u64();
  chunk.end_time = r.u64();
  chunk.uncompressed_size = r.u64();
  chunk.uncompressed_crc = r.u32();
  chunk.compression = r.string();
  chunk.compressed = r.bytes(r.u64());
  return r.ok() ? std::optional<ChunkHeader>(chunk) : std::nullopt;
}

Status check_chunk_crc(const ChunkHeader& chunk, std::string_view records, uint64_t offset, bool validate_crc) {
  if (!validate_crc || chunk.uncompressed_crc == 0) return ok_status();
  const uint32_t crc = format::crc32_of(records);
  if (crc == chunk.uncompressed_crc) return ok_status();
  return Error(fmt::format("chunk at byte {}: CRC mismatch (stored {:#010x}, computed {:#010x}): the file is corrupted", offset,
                           chunk.uncompressed_crc, crc));
}

// Decompresses a chunk record's content, checking its CRC; `offset` names it in errors.
Result<std::string> chunk_records(const ChunkHeader& chunk, uint64_t offset, bool validate_crc) {
  auto records = decompress(chunk.compression, chunk.compressed, chunk.uncompressed_size);
  if (!records) return Error(fmt::format("chunk at byte {}: {}", offset, records.error().message));
  HANZO_RETURN_IF_ERROR(check_chunk_crc(chunk, *records, offset, validate_crc));
  return records;
}

struct MessageHeader {
  uint16_t channel_id = 0;
  uint32_t sequence = 0;
  uint64_t log_time = 0;
  uint64_t publish_time = 0;
  std::string_view data;
};

std::optional<MessageHeader> parse_message(std::string_view content) {
  ByteReader r(content);
  MessageHeader m;
  m.channel_id = r.u16();
  m.sequence = r.u32();
  m.log_time = r.u64();
  m.publish_time = r.u64();
  m.data = r.rest();
  return r.ok() ? std::optional<MessageHeader>(m) : std::nullopt;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Opening: footer -> summary, or a linear scan when there is no usable summary.

Result<std::string> McapReader::read_at(uint64_t offset, uint64_t length) const {
  if (offset > file_size_ || length > file_size_ - offset) {
    return Error(fmt::format("{}: read of {} bytes at byte {} runs past the end of the file ({} bytes)", path_, length,
                             offset, file_size_));
  }
  std::string bytes(length, '\0');
  uint64_t done = 0;
  while (done < length) {
    const ssize_t n = ::pread(fd_, bytes.data() + done, length - done, static_cast<off_t>(offset + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return Error(fmt::format("{}: read error at byte {} ({})", path_, offset + done, std::strerror(errno)));
    done += static_cast<uint64_t>(n);
  }
  return bytes;
}

Result<std::unique_ptr<McapReader>> McapReader::open(const std::string& path, const McapReaderConfig& config) {
  std::unique_ptr<McapReader> reader(new McapReader());
  reader->config_ = config;
  reader->path_ = path;
  if (crypto::is_encrypted_file(path)) {
    // Encrypted at rest (crypto/file_encryption.hpp): read a decrypted copy held in memory.
    std::vector<crypto::EncryptionKey> keys = config.decryption_keys;
    if (keys.empty()) HANZO_ASSIGN_OR_RETURN(keys, crypto::keys_from_environment());
    if (keys.empty()) return Error(fmt::format("{}: the file is encrypted; set HANZO_ENCRYPTION_KEY to its key", path));
    HANZO_ASSIGN_OR_RETURN(reader->fd_, crypto::decrypt_to_memory_file(path, keys));
  } else {
    reader->fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  }
  if (reader->fd_ < 0) return Error(fmt::format("{}: cannot open file ({})", path, std::strerror(errno)));
  struct stat info {};
  if (::fstat(reader->fd_, &info) != 0) return Error(fmt::format("{}: cannot stat ({})", path, std::strerror(errno)));
  reader->file_size_ = static_cast<uint64_t>(info.st_size);

  // Leading magic and header.
  if (reader->file_size_ < format::kMagicSize + format::kRecordPrefixSize) {
    return Error(fmt::format("{}: not an MCAP file ({} bytes, too short for magic and header)", path, reader->file_size_));
  }
  std::string start;
  HANZO_ASSIGN_OR_RETURN(start, reader->read_at(0, format::kMagicSize + format::kRecordPrefixSize));
  if (start.compare(0, 5, format::kMagic, 5) != 0 || start.compare(6, 2, format::kMagic + 6, 2) != 0) {
    return Error(fmt::format("{}: not an MCAP file (bad magic bytes)", path));
  }
  if (start[5] != '0') return Error(fmt::format("{}: unsupported MCAP major version '{}' (this reader reads version 0)", path, start[5]));
  ByteReader prefix(std::string_view(start).substr(format::kMagicSize));
  if (prefix.u8() != format::kHeader) return Error(fmt::format("{}: the first record is not an MCAP Header", path));
  const uint64_t header_length = prefix.u64();
  std::string header;
  HANZO_ASSIGN_OR_RETURN(header, with_context(reader->read_at(format::kMagicSize + format::kRecordPrefixSize, header_length),
                                              "MCAP header"));
  ByteReader h(header);
  reader->profile_ = h.string();
  reader->library_ = h.string();
  if (!h.ok()) return Error(fmt::format("{}: malformed MCAP Header record", path));
  reader->data_start_ = format::kMagicSize + format::kRecordPrefixSize + header_length;

  // Footer and trailing magic.
  bool has_footer = false;
  uint64_t summary_start = 0, summary_offset_start = 0;
  uint32_t summary_crc = 0;
  const uint64_t footer_offset = reader->file_size_ >= reader->data_start_ + format::kFooterTailSize
                                     ? reader->file_size_ - format::kFooterTailSize
                                     : 0;
  if (footer_offset != 0) {
    std::string tail;
    HANZO_ASSIGN_OR_RETURN(tail, reader->read_at(footer_offset, format::kFooterTailSize));
    ByteReader f(tail);
    const uint8_t opcode = f.u8();
    const uint64_t length = f.u64();
    summary_start = f.u64();
    summary_offset_start = f.u64();
    summary_crc = f.u32();
    has_footer = opcode == format::kFooter && length == format::kFooterContentSize &&
                 tail.compare(format::kRecordPrefixSize + format::kFooterContentSize, format::kMagicSize, format::kMagic,
                              format::kMagicSize) == 0;
  }
  if (has_footer && summary_start != 0) {
    if (summary_start < reader->data_start_ || summary_start > footer_offset || summary_offset_start > footer_offset) {
      return Error(fmt::format("{}: footer points outside the file (summary at byte {})", path, summary_start));
    }
    HANZO_RETURN_IF_ERROR(reader->read_summary(summary_start, footer_offset, summary_crc));
    if (!reader->chunk_indexes_.empty() || reader->statistics_.message_count == 0) {
      for (const ChunkIndex& index : reader->chunk_indexes_) {
        reader->blocks_.push_back(
            {index.chunk_start_offset, index.chunk_length, index.message_start_time, index.message_end_time, true});
      }
      std::stable_sort(reader->blocks_.begin(), reader->blocks_.end(),
                       [](const Block& a, const Block& b) { return a.start_time < b.start_time; });
      return reader;
    }
    // A summary without chunk indexes (an unchunked file): find the messages by scanning.
  }
  HANZO_RETURN_IF_ERROR(reader->scan_data_section());
  if (!has_footer && !reader->warning_) {
    reader->warning_ = fmt::format("{}: no MCAP footer (the recording was cut off?); read all complete records", path);
  }
  if (reader->warning_) logger()->warn("{}", *reader->warning_);
  return reader;
}

McapReader::~McapReader() {
  if (fd_ >= 0) ::close(fd_);
}

Status McapReader::read_summary(uint64_t summary_start, uint64_t footer_offset, uint32_t summary_crc) {
  // The summary CRC covers [summary_start, footer's CRC field): the summary, the summary
  // offsets and the footer's opcode, length and two offsets.
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, read_at(summary_start, footer_offset - summary_start + format::kRecordPrefixSize + 16));
  if (config_.validate_crcs && summary_crc != 0) {
    const uint32_t crc = format::crc32_of(bytes);
    if (crc != summary_crc) {
      return Error(fmt::format("{}: summary CRC mismatch (stored {:#010x}, computed {:#010x}): the file is corrupted", path_,
                               summary_crc, crc));
    }
  }
  ByteReader reader(std::string_view(bytes).substr(0, footer_offset - summary_start));
  bool have_statistics = false;
  while (reader.remaining() > 0) {
    const uint64_t offset = summary_start + reader.position();
    const auto record = next_record(reader);
    if (!record) return Error(fmt::format("{}: malformed summary record at byte {}", path_, offset));
    auto malformed = [&](const char* what) {
      return Error(fmt::format("{}: malformed {} record in the summary at byte {}", path_, what, offset));
    };
    ByteReader r(record->content);
    switch (record->opcode) {
      case format::kSchema: {
        auto schema = parse_schema(record->content);
        if (!schema) return malformed("Schema");
        schemas_[schema->id] = std::move(*schema);
        break;
      }
      case format::kChannel: {
        auto channel = parse_channel(record->content);
        if (!channel) return malformed("Channel");
        channels_[channel->id] = std::move(*channel);
        break;
      }
      case format::kStatistics: {
        statistics_.message_count = r.u64();
        statistics_.schema_count = r.u16();
        statistics_.channel_count = r.u32();
        statistics_.attachment_count = r.u32();
        statistics_.metadata_count = r.u32();
        statistics_.chunk_count = r.u32();
        statistics_.message_start_time = r.u64();
        statistics_.message_end_time = r.u64();
        statistics_.channel_message_counts = r.id_count_map();
        if (!r.ok()) return malformed("Statistics");
        have_statistics = true;
        break;
      }
      case format::kChunkIndex: {
        ChunkIndex index;
        index.message_start_time = r.u64();
        index.message_end_time = r.u64();
        index.chunk_start_offset = r.u64();
        index.chunk_length = r.u64();
        index.message_index_offsets = r.id_count_map();
        index.message_index_length = r.u64();
        index.compression = r.string();
        index.compressed_size = r.u64();
        index.uncompressed_size = r.u64();
        if (!r.ok()) return malformed("ChunkIndex");
        if (index.chunk_start_offset < data_start_ || index.chunk_start_offset > file_size_ ||
            index.chunk_length > file_size_ - index.chunk_start_offset) {
          return Error(fmt::format("{}: chunk index at byte {} points outside the file", path_, offset));
        }
        chunk_indexes_.push_back(std::move(index));
        break;
      }
      case format::kMetadataIndex: {
        const uint64_t metadata_offset = r.u64();
        const uint64_t metadata_length = r.u64();
        if (!r.ok()) return malformed("MetadataIndex");
        std::string metadata_record;
        HANZO_ASSIGN_OR_RETURN(metadata_record, read_at(metadata_offset, metadata_length));
        ByteReader m(metadata_record);
        const auto inner = next_record(m);
        std::optional<Metadata> metadata;
        if (inner && inner->opcode == format::kMetadata) metadata = parse_metadata(inner->content);
        if (!metadata) {  // seen in files of other writers; the metadata is not needed to read messages
          logger()->warn("{}: metadata index at byte {} does not point at a Metadata record; ignored", path_, offset);
          break;
        }
        metadata_.push_back(std::move(*metadata));
        break;
      }
      default:
        break;  // attachment indexes, summary offsets, private records: not needed here
    }
  }
  if (!have_statistics) {
    statistics_.schema_count = static_cast<uint16_t>(schemas_.size());
    statistics_.channel_count = static_cast<uint32_t>(channels_.size());
    statistics_.chunk_count = static_cast<uint32_t>(chunk_indexes_.size());
  }
  return ok_status();
}

Status McapReader::scan_data_section() {
  // Rebuild what a summary would hold. One record (at most one chunk) is in memory at a time.
  schemas_.clear();
  channels_.clear();
  chunk_indexes_.clear();
  blocks_.clear();
  metadata_.clear();
  statistics_ = {};
  uint64_t position = data_start_;
  uint64_t records = 0;
  bool data_end_seen = false;
  std::optional<Block> bare_run;  // consecutive bare Message records
  auto count_message = [this](const MessageHeader& m) {
    if (statistics_.message_count == 0 || m.log_time < statistics_.message_start_time) statistics_.message_start_time = m.log_time;
    statistics_.message_end_time = std::max(statistics_.message_end_time, m.log_time);
    ++statistics_.message_count;
    ++statistics_.channel_message_counts[m.channel_id];
  };
  auto close_run = [&] {
    if (bare_run) blocks_.push_back(*bare_run);
    bare_run.reset();
  };
  while (position + format::kRecordPrefixSize <= file_size_) {
    std::string prefix_bytes;
    HANZO_ASSIGN_OR_RETURN(prefix_bytes, read_at(position, format::kRecordPrefixSize));
    ByteReader prefix(prefix_bytes);
    const uint8_t opcode = prefix.u8();
    const uint64_t length = prefix.u64();
    if (length > file_size_ - position - format::kRecordPrefixSize) break;  // cut off inside this record
    if (opcode == format::kDataEnd || opcode == format::kFooter) {
      data_end_seen = true;
      break;
    }
    const uint64_t record_size = format::kRecordPrefixSize + length;
    const bool needs_content = opcode == format::kSchema || opcode == format::kChannel || opcode == format::kChunk ||
                               opcode == format::kMessage || opcode == format::kMetadata;
    if (opcode != format::kMessage) close_run();
    if (needs_content) {
      std::string content;
      HANZO_ASSIGN_OR_RETURN(content, read_at(position + format::kRecordPrefixSize, length));
      auto malformed = [&](const char* what) {
        return Error(fmt::format("{}: malformed {} record at byte {}", path_, what, position));
      };
      if (opcode == format::kSchema) {
        auto schema = parse_schema(content);
        if (!schema) return malformed("Schema");
        schemas_[schema->id] = std::move(*schema);
      } else if (opcode == format::kChannel) {
        auto channel = parse_channel(content);
        if (!channel) return malformed("Channel");
        channels_[channel->id] = std::move(*channel);
      } else if (opcode == format::kMetadata) {
        auto metadata = parse_metadata(content);
        if (!metadata) return malformed("Metadata");
        metadata_.push_back(std::move(*metadata));
      } else if (opcode == format::kMessage) {
        auto message = parse_message(content);
        if (!message) return malformed("Message");
        count_message(*message);
        if (!bare_run) bare_run = Block{position, 0, message->log_time, message->log_time, false};
        bare_run->length = position + record_size - bare_run->offset;
        bare_run->start_time = std::min(bare_run->start_time, message->log_time);
        bare_run->end_time = std::max(bare_run->end_time, message->log_time);
      } else {  // Chunk: index it, and learn its schemas, channels and message counts
        auto chunk = parse_chunk(content);
        if (!chunk) return malformed("Chunk");
        std::string inner;
        HANZO_ASSIGN_OR_RETURN(inner, with_context(chunk_records(*chunk, position, config_.validate_crcs), path_));
        ByteReader r(inner);
        ChunkIndex index;
        index.chunk_start_offset = position;
        index.chunk_length = record_size;
        index.compression = chunk->compression;
        index.compressed_size = chunk->compressed.size();
        index.uncompressed_size = chunk->uncompressed_size;
        bool any_message = false;
        while (r.remaining() > 0) {
          const auto record = next_record(r);
          if (!record) return Error(fmt::format("{}: malformed record inside the chunk at byte {}", path_, position));
          if (record->opcode == format::kSchema) {
            if (auto schema = parse_schema(record->content)) schemas_[schema->id] = std::move(*schema);
          } else if (record->opcode == format::kChannel) {
            if (auto channel = parse_channel(record->content)) channels_[channel->id] = std::move(*channel);
          } else if (record->opcode == format::kMessage) {
            auto message = parse_message(record->content);
            if (!message) return Error(fmt::format("{}: malformed message inside the chunk at byte {}", path_, position));
            count_message(*message);
            index.message_start_time = any_message ? std::min(index.message_start_time, message->log_time) : message->log_time;
            index.message_end_time = std::max(index.message_end_time, message->log_time);
            any_message = true;
          }
        }
        blocks_.push_back({position, record_size, index.message_start_time, index.message_end_time, true});
        chunk_indexes_.push_back(std::move(index));
        ++statistics_.chunk_count;
      }
    }
    position += record_size;
    ++records;
  }
  close_run();
  statistics_.schema_count = static_cast<uint16_t>(schemas_.size());
  statistics_.channel_count = static_cast<uint32_t>(channels_.size());
  statistics_.metadata_count = static_cast<uint32_t>(metadata_.size());
  std::stable_sort(blocks_.begin(), blocks_.end(), [](const Block& a, const Block& b) { return a.start_time < b.start_time; });
  if (!data_end_seen) {
    warning_ = fmt::format(
        "{}: file is truncated: read {} complete records ({} messages) up to byte {} of {}; the rest is lost", path_,
        records, statistics_.message_count, position, file_size_);
  }
  return ok_status();
}

const Channel* McapReader::channel_by_topic(const std::string& topic) const {
  for (const auto& [id, channel] : channels_) {
    if (channel.topic == topic) return &channel;
  }
  return nullptr;
}

// ---------------------------------------------------------------------------------------------
// Iteration: a k-way merge over the blocks, loading a block only when its start time is not
// after the earliest message still waiting.

struct MessageIterator::State {
  struct Loaded {
    std::string storage;       // the bytes read (uncompressed chunk, bare block) or decompressed
    std::string_view records;  // the records, inside storage
  };
  struct Pending {
    uint64_t log_time;
    std::size_t block_order;
    std::size_t record_offset;
    MessageHeader header;
    std::shared_ptr<const Loaded> block;  // keeps the block's bytes alive
    bool operator>(const Pending& other) const {
      if (log_time != other.log_time) return log_time > other.log_time;
      if (block_order != other.block_order) return block_order > other.block_order;
      return record_offset > other.record_offset;
    }
  };

  const McapReader* reader = nullptr;
  ReadOptions options;
  std::set<uint16_t> channel_filter;  // empty: all
  std::size_t next_block = 0;
  std::priority_queue<Pending, std::vector<Pending>, std::greater<Pending>> queue;
  std::shared_ptr<const Loaded> current;  // the block of the message last returned
  bool failed = false;

  Status load(std::size_t block_index) {
    const McapReader::Block& block = reader->blocks_[block_index];
    std::string bytes;
    HANZO_ASSIGN_OR_RETURN(bytes, reader->read_at(block.offset, block.length));
    auto loaded = std::make_shared<Loaded>();
    if (block.is_chunk) {
      ByteReader r(bytes);
      const auto record = next_record(r);
      std::optional<ChunkHeader> chunk;
      if (record && record->opcode == format::kChunk) chunk = parse_chunk(record->content);
      if (!chunk) return Error(fmt::format("{}: no valid Chunk record at byte {}", reader->path_, block.offset));
      if (chunk->compression.empty()) {
        // Uncompressed: the records are read in place, without a copy.
        if (chunk->compressed.size() != chunk->uncompressed_size) {
          return Error(fmt::format("{}: chunk at byte {}: uncompressed chunk holds {} bytes, its header says {}", reader->path_,
                                   block.offset, chunk->compressed.size(), chunk->uncompressed_size));
        }
        HANZO_RETURN_IF_ERROR(with_context(check_chunk_crc(*chunk, chunk->compressed, block.offset, reader->config_.validate_crcs),
                                           reader->path_));
        const std::size_t begin = static_cast<std::size_t>(chunk->compressed.data() - bytes.data());
        loaded->storage = std::move(bytes);
        loaded->records = std::string_view(loaded->storage).substr(begin, chunk->uncompressed_size);
      } else {
        HANZO_ASSIGN_OR_RETURN(loaded->storage,
                               with_context(chunk_records(*chunk, block.offset, reader->config_.validate_crcs), reader->path_));
        loaded->records = loaded->storage;
      }
    } else {
      loaded->storage = std::move(bytes);
      loaded->records = loaded->storage;
    }
    ByteReader r(loaded->records);
    while (r.remaining() > 0) {
      const std::size_t offset = r.position();
      const auto record = next_record(r);
      if (!record) return Error(fmt::format("{}: malformed record in the block at byte {}", reader->path_, block.offset));
      if (record->opcode != format::kMessage) continue;
      const auto message = parse_message(record->content);
      if (!message) return Error(fmt::format("{}: malformed Message record in the block at byte {}", reader->path_, block.offset));
      if (message->log_time < options.start_time || message->log_time > options.end_time) continue;
      if (!channel_filter.empty() && channel_filter.count(message->channel_id) == 0) continue;
      if (reader->channels_.count(message->channel_id) == 0) {
        return Error(fmt::format("{}: message on undefined channel {} in the block at byte {}", reader->path_,
                                 message->channel_id, block.offset));
      }
      queue.push({message->log_time, block_index, offset, *message, loaded});
    }
    return ok_status();
  }
};

MessageIterator::MessageIterator(std::unique_ptr<State> state) : state_(std::move(state)) {}
MessageIterator::~MessageIterator() = default;
MessageIterator::MessageIterator(MessageIterator&&) noexcept = default;
MessageIterator& MessageIterator::operator=(MessageIterator&&) noexcept = default;

Result<bool> MessageIterator::next(MessageView& message) {
  State& s = *state_;
  if (s.failed) return false;
  const auto& blocks = s.reader->blocks_;
  while (s.next_block < blocks.size() && (s.queue.empty() || blocks[s.next_block].start_time <= s.queue.top().log_time)) {
    const std::size_t index = s.next_block++;
    if (blocks[index].end_time < s.options.start_time || blocks[index].start_time > s.options.end_time) continue;
    if (Status status = s.load(index); !status) return status.error();  // the block is skipped; the next call goes on
  }
  if (s.queue.empty()) return false;
  const State::Pending top = s.queue.top();
  s.queue.pop();
  s.current = top.block;
  const Channel& channel = s.reader->channels_.at(top.header.channel_id);
  message.channel = &channel;
  const auto schema = s.reader->schemas_.find(channel.schema_id);
  message.schema = schema == s.reader->schemas_.end() ? nullptr : &schema->second;
  message.sequence = top.header.sequence;
  message.log_time = top.header.log_time;
  message.publish_time = top.header.publish_time;
  message.data = top.header.data;
  return true;
}

MessageIterator McapReader::messages(const ReadOptions& options) const {
  auto state = std::make_unique<MessageIterator::State>();
  state->reader = this;
  state->options = options;
  for (const auto& [id, channel] : channels_) {
    if (options.topics.count(channel.topic) != 0) state->channel_filter.insert(id);  // all publishers of a topic
  }
  if (!options.topics.empty() && state->channel_filter.empty()) state->failed = true;  // no such topic: nothing to read
  return MessageIterator(std::move(state));
}

}  // namespace hanzo::fusion::io::mcap
