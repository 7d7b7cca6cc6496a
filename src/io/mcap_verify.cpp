// McapReader::verify(): a full linear pass that checks every CRC and index of a file.

#include <fmt/format.h>

#include "hanzo/fusion/io/mcap.hpp"
#include "mcap_compression.hpp"
#include "mcap_format.hpp"

namespace hanzo::fusion::io::mcap {

using format::ByteReader;

Result<VerifyReport> McapReader::verify() const {
  VerifyReport report;
  uint32_t data_crc = 0;
  std::string head;
  HANZO_ASSIGN_OR_RETURN(head, read_at(0, data_start_));
  data_crc = format::crc32_update(data_crc, head);
  uint64_t position = data_start_;
  std::string last_chunk_records;  // for checking the message indexes that follow a chunk
  uint64_t last_chunk_offset = 0;
  while (true) {
    if (position + format::kRecordPrefixSize > file_size_) {
      return Error(fmt::format("{}: data section ends at byte {} without a DataEnd record (truncated file)", path_, position));
    }
    std::string prefix;
    HANZO_ASSIGN_OR_RETURN(prefix, read_at(position, format::kRecordPrefixSize));
    ByteReader p(prefix);
    const uint8_t opcode = p.u8();
    const uint64_t length = p.u64();
    if (length > file_size_ - position - format::kRecordPrefixSize) {
      return Error(fmt::format("{}: record at byte {} claims {} bytes, past the end of the file", path_, position, length));
    }
    std::string content;
    HANZO_ASSIGN_OR_RETURN(content, read_at(position + format::kRecordPrefixSize, length));
    ++report.records;
    if (opcode == format::kDataEnd) {
      ByteReader r(content);
      const uint32_t stored = r.u32();
      if (stored != 0) {
        if (stored != data_crc) {
          return Error(fmt::format("{}: data section CRC mismatch (stored {:#010x}, computed {:#010x})", path_, stored, data_crc));
        }
        report.data_section_crc_checked = true;
      }
      break;
    }
    data_crc = format::crc32_update(format::crc32_update(data_crc, prefix), content);
    ByteReader r(content);
    if (opcode == format::kChunk) {
      const uint64_t start = r.u64();
      const uint64_t end = r.u64();
      const uint64_t uncompressed_size = r.u64();
      const uint32_t crc = r.u32();
      const std::string_view compression = r.string();
      const std::string_view compressed = r.bytes(r.u64());
      if (!r.ok()) return Error(fmt::format("{}: malformed Chunk record at byte {}", path_, position));
      auto records = decompress(compression, compressed, uncompressed_size);
      if (!records) return Error(fmt::format("{}: chunk at byte {}: {}", path_, position, records.error().message));
      if (crc != 0 && format::crc32_of(*records) != crc) {
        return Error(fmt::format("{}: chunk at byte {}: CRC mismatch (stored {:#010x}, computed {:#010x})", path_, position,
                                 crc, format::crc32_of(*records)));
      }
      ByteReader inner(*records);
      while (inner.remaining() > 0) {
        const uint8_t inner_opcode = inner.u8();
        const std::string_view inner_content = inner.bytes(inner.u64());
        if (!inner.ok()) return Error(fmt::format("{}: malformed record inside the chunk at byte {}", path_, position));
        if (inner_opcode != format::kMessage) continue;
        ByteReader m(inner_content);
        m.u16();
        m.u32();
        const uint64_t log_time = m.u64();
        if (!m.ok() || inner_content.size() < 22) return Error(fmt::format("{}: malformed message in the chunk at byte {}", path_, position));
        if (log_time < start || log_time > end) {
          return Error(fmt::format("{}: chunk at byte {} holds a message at {} ns outside its range {}..{}", path_, position,
                                   log_time, start, end));
        }
        ++report.messages;
      }
      ++report.chunks;
      last_chunk_records = std::move(*records);
      last_chunk_offset = position;
    } else if (opcode == format::kMessageIndex) {
      r.u16();
      ByteReader entries(r.string());
      if (!r.ok()) return Error(fmt::format("{}: malformed MessageIndex record at byte {}", path_, position));
      while (entries.remaining() > 0) {
        const uint64_t log_time = entries.u64();
        const uint64_t offset = entries.u64();
        ByteReader at(std::string_view(last_chunk_records).substr(std::min<uint64_t>(offset, last_chunk_records.size())));
        const uint8_t target = at.u8();
        at.u64();
        at.u16();
        at.u32();
        if (!entries.ok() || !at.ok() || target != format::kMessage || at.u64() != log_time) {
          return Error(fmt::format("{}: message index at byte {} does not match the messages of the chunk at byte {}", path_,
                                   position, last_chunk_offset));
        }
      }
    } else if (opcode == format::kMessage) {
      ++report.messages;
    }
    position += format::kRecordPrefixSize + length;
  }
  // Summary CRC (the footer's): re-read through open()'s check.
  const uint64_t footer_offset = file_size_ - format::kFooterTailSize;
  std::string tail;
  HANZO_ASSIGN_OR_RETURN(tail, read_at(footer_offset, format::kFooterTailSize));
  ByteReader f(tail);
  f.u8();
  f.u64();
  const uint64_t summary_start = f.u64();
  f.u64();
  const uint32_t summary_crc = f.u32();
  if (summary_start != 0 && summary_crc != 0) {
    std::string summary;
    HANZO_ASSIGN_OR_RETURN(summary, read_at(summary_start, footer_offset - summary_start + format::kRecordPrefixSize + 16));
    if (format::crc32_of(summary) != summary_crc) return Error(fmt::format("{}: summary CRC mismatch", path_));
    report.summary_crc_checked = true;
  }
  return report;
}

}  // namespace hanzo::fusion::io::mcap
