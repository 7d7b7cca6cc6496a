#pragma once
// MCAP files (https://mcap.dev/spec, major version 0): the container hanzo-fusion sensor logs
// are stored in. This layer knows records, chunks, compression and indexes; it does not know
// what the message bytes mean (sensor_log.hpp adds the hanzo.fusion.v1 protobuf messages).
//
// Files written here are chunked (zstd, lz4 or uncompressed chunks), carry a Message Index per
// channel after every chunk, and end with a summary section (schemas, channels, statistics,
// chunk indexes, metadata indexes), summary offsets and a footer, with every CRC filled in
// (chunk data, data section, summary). So other MCAP tools can list channels and seek by time
// without reading the whole file.
//
// Reading (McapReader) opens a file by its footer and summary when it has them; a file without
// a summary (a recording cut off by a crash, or a writer that skips it) is scanned linearly up
// to the last complete record, with a warning. Messages of all channels come out merged in
// log-time order (ties in file order) while holding only the chunks that overlap in time in
// memory, so a 10 GB log is never loaded whole.

#include <cstdint>
#include <cstdio>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/crypto/file_encryption.hpp"

namespace hanzo::fusion::io::mcap {

enum class Compression { kNone, kLz4, kZstd };
/// "" (none), "lz4", "zstd": the names MCAP stores in chunk records.
const char* compression_name(Compression compression);
/// Accepts "none" for kNone as well as "".
Result<Compression> compression_from_name(std::string_view name);

struct Schema {
  uint16_t id = 0;
  std::string name;      ///< e.g. "hanzo.fusion.v1.ImuMessage"
  std::string encoding;  ///< e.g. "protobuf"
  std::string data;      ///< e.g. a serialized google.protobuf.FileDescriptorSet
};

struct Channel {
  uint16_t id = 0;
  uint16_t schema_id = 0;  ///< 0: no schema
  std::string topic;
  std::string message_encoding;  ///< e.g. "protobuf"
  std::map<std::string, std::string> metadata;
};

/// A message as read: `data` points into the reader's buffers and stays valid until the next
/// call to MessageIterator::next().
struct MessageView {
  const Channel* channel = nullptr;
  const Schema* schema = nullptr;  ///< nullptr when the channel has no schema
  uint32_t sequence = 0;
  uint64_t log_time = 0;      ///< ns
  uint64_t publish_time = 0;  ///< ns
  std::string_view data;
};

struct Statistics {
  uint64_t message_count = 0;
  uint16_t schema_count = 0;
  uint32_t channel_count = 0;
  uint32_t attachment_count = 0;
  uint32_t metadata_count = 0;
  uint32_t chunk_count = 0;
  uint64_t message_start_time = 0;  ///< ns, 0 when there are no messages
  uint64_t message_end_time = 0;
  std::map<uint16_t, uint64_t> channel_message_counts;
};

struct ChunkIndex {
  uint64_t message_start_time = 0;
  uint64_t message_end_time = 0;
  uint64_t chunk_start_offset = 0;  ///< file offset of the Chunk record's opcode
  uint64_t chunk_length = 0;        ///< whole record, opcode and length included
  std::map<uint16_t, uint64_t> message_index_offsets;
  uint64_t message_index_length = 0;
  std::string compression;
  uint64_t compressed_size = 0;
  uint64_t uncompressed_size = 0;
};

struct Metadata {
  std::string name;
  std::map<std::string, std::string> values;
};

struct McapWriterConfig {
  Compression compression = Compression::kZstd;
  /// A chunk is closed when its uncompressed records reach this size (bytes). Larger chunks
  /// compress better; smaller ones make seeking finer. 4 MiB holds one 120k-point scan.
  std::size_t chunk_size = 4u << 20;
  /// zstd level 1..19 (1: fastest; 3 is zstd's default) / lz4 level 0..12 (0: fast mode).
  int compression_level = 1;
  std::string profile;  ///< MCAP profile ("" for protobuf payloads; "ros1", "ros2" exist)
  std::string library = "hanzo-fusion";
};

/// Writes one MCAP file. Not thread-safe. Call close() to finish the file (summary, footer);
/// the destructor closes too but can only log a failure. A file that is never closed (crash)
/// is still readable up to its last complete chunk.
class McapWriter {
 public:
  /// Creates (truncates) `path` and writes the magic and header.
  static Result<std::unique_ptr<McapWriter>> open(const std::string& path, const McapWriterConfig& config = {});
  ~McapWriter();
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  /// Registers a schema and returns its id (>= 1). The same (name, encoding, data) twice
  /// returns the first id.
  Result<uint16_t> add_schema(const std::string& name, const std::string& encoding, const std::string& data);
  /// Registers a channel (schema_id 0 or a registered schema) and returns its id. Fails when
  /// the topic is already registered with another schema or encoding; the same registration
  /// twice returns the first id.
  Result<uint16_t> add_channel(uint16_t schema_id, const std::string& topic, const std::string& message_encoding,
                               const std::map<std::string, std::string>& metadata = {});
  /// Appends a message to the current chunk. Messages may come in any time order; the reader
  /// merges them. `sequence` 0 means "count per channel" (1, 2, 3, ...).
  Status write(uint16_t channel_id, uint64_t log_time, uint64_t publish_time, std::string_view data, uint32_t sequence = 0);
  /// A Metadata record (e.g. provenance: source files, importer, settings).
  Status add_metadata(const Metadata& metadata);
  /// Flushes the open chunk and writes the summary, summary offsets, footer and magic.
  Status close();

  const Statistics& statistics() const { return statistics_; }
  uint64_t bytes_written() const { return file_offset_; }

 private:
  McapWriter() = default;
  Status write_bytes(std::string_view bytes);
  Status flush_chunk();

  McapWriterConfig config_;
  std::string path_;
  std::FILE* file_ = nullptr;
  bool closed_ = false;
  uint64_t file_offset_ = 0;
  uint32_t data_crc_ = 0;
  std::vector<Schema> schemas_;
  std::vector<Channel> channels_;
  std::map<uint16_t, uint32_t> sequence_counters_;
  // The open chunk: its records (uncompressed), time range, message index, and which
  // schemas/channels it already defines (every chunk repeats those it uses, so a chunk can be
  // read on its own).
  std::string chunk_records_;
  uint64_t chunk_start_time_ = UINT64_MAX;
  uint64_t chunk_end_time_ = 0;
  std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>> chunk_message_index_;
  std::set<uint16_t> chunk_schemas_;
  std::set<uint16_t> chunk_channels_;
  std::vector<ChunkIndex> chunk_indexes_;
  std::vector<std::pair<uint64_t, uint64_t>> metadata_index_;  // (offset, length)
  std::vector<std::string> metadata_names_;
  Statistics statistics_;
};

struct McapReaderConfig {
  /// Check chunk CRCs as chunks are decompressed and the summary CRC at open (a mismatch is an
  /// error naming the offset). The data-section CRC is checked by McapReader::verify().
  bool validate_crcs = true;
  /// A file encrypted at rest (crypto/file_encryption.hpp) is decrypted into memory with these
  /// keys, or with $HANZO_ENCRYPTION_KEY's when empty; nothing decrypted reaches the disk.
  std::vector<crypto::EncryptionKey> decryption_keys;
};

/// Which messages to read: log_time in [start_time, end_time] on the listed topics (all when empty).
struct ReadOptions {
  uint64_t start_time = 0;
  uint64_t end_time = UINT64_MAX;
  std::set<std::string> topics;
};

class McapReader;

/// Yields messages in log-time order. Holds the decompressed chunks whose time ranges overlap
/// the current read position, nothing more. The McapReader must outlive its iterators.
class MessageIterator {
 public:
  /// true and fills `message` when there is one; false at the end; an error for a corrupted
  /// chunk (CRC mismatch, bad compression, malformed record), naming its file offset. The
  /// corrupted chunk's messages are lost (those before a malformed record still come out); the
  /// next call goes on with the rest of the file.
  Result<bool> next(MessageView& message);
  ~MessageIterator();
  MessageIterator(MessageIterator&&) noexcept;
  MessageIterator& operator=(MessageIterator&&) noexcept;

 private:
  friend class McapReader;
  struct State;
  explicit MessageIterator(std::unique_ptr<State> state);
  std::unique_ptr<State> state_;
};

struct VerifyReport {
  uint64_t records = 0;
  uint64_t chunks = 0;
  uint64_t messages = 0;
  bool data_section_crc_checked = false;  ///< false when the file stores 0 (not computed)
  bool summary_crc_checked = false;
};

class McapReader {
 public:
  /// Opens `path` and reads its summary (or scans it when there is none). Fails for a file that
  /// is not MCAP (bad magic), an unsupported major version, a malformed summary or a summary
  /// CRC mismatch.
  static Result<std::unique_ptr<McapReader>> open(const std::string& path, const McapReaderConfig& config = {});
  ~McapReader();
  McapReader(const McapReader&) = delete;
  McapReader& operator=(const McapReader&) = delete;

  const std::string& profile() const { return profile_; }
  const std::string& library() const { return library_; }
  const std::map<uint16_t, Schema>& schemas() const { return schemas_; }
  const std::map<uint16_t, Channel>& channels() const { return channels_; }
  /// From the summary, or counted by the scan when the file had none.
  const Statistics& statistics() const { return statistics_; }
  const std::vector<ChunkIndex>& chunk_indexes() const { return chunk_indexes_; }
  const std::vector<Metadata>& metadata() const { return metadata_; }
  uint64_t file_size() const { return file_size_; }
  /// Set when the file had no summary or was cut off: what was recovered and from where.
  const std::optional<std::string>& warning() const { return warning_; }
  /// The channel with this topic, or nullptr.
  const Channel* channel_by_topic(const std::string& topic) const;

  MessageIterator messages(const ReadOptions& options = {}) const;
  /// Raw bytes of the file at [offset, offset + length) (for index records; fails past the end).
  Result<std::string> read_range(uint64_t offset, uint64_t length) const { return read_at(offset, length); }
  /// Reads every record from the start, checking every CRC (data section, chunks, summary) and
  /// that chunk message indexes point at messages. For `hanzo-fusion log info --verify` and tests.
  Result<VerifyReport> verify() const;

 private:
  friend class MessageIterator;
  McapReader() = default;
  Status read_summary(uint64_t summary_start, uint64_t footer_offset, uint32_t summary_crc);
  Status scan_data_section();

  // A stretch of the data section the iterator loads at once: a Chunk record, or (in files
  // written without chunks) a run of bare Message records.
  struct Block {
    uint64_t offset = 0;
    uint64_t length = 0;
    uint64_t start_time = 0;
    uint64_t end_time = 0;
    bool is_chunk = true;
  };
  std::vector<Block> blocks_;  // sorted by start_time, then offset

  /// Reads `length` bytes at `offset` (fails past the end of the file).
  Result<std::string> read_at(uint64_t offset, uint64_t length) const;

  McapReaderConfig config_;
  std::string path_;
  int fd_ = -1;
  uint64_t file_size_ = 0;
  uint64_t data_start_ = 0;  // first byte after the header record
  std::string profile_;
  std::string library_;
  std::map<uint16_t, Schema> schemas_;
  std::map<uint16_t, Channel> channels_;
  Statistics statistics_;
  std::vector<ChunkIndex> chunk_indexes_;
  std::vector<Metadata> metadata_;
  std::optional<std::string> warning_;
};

}  // namespace hanzo::fusion::io::mcap
