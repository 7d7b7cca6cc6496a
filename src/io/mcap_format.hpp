#pragma once
// MCAP wire primitives (little-endian integers, uint32-prefixed strings and maps, records of
// opcode + uint64 length + content) and the CRC-32 MCAP uses (zlib's, ISO-HDLC polynomial).

#include <cstdint>
#include <cstring>
#include <map>
#include <string>
#include <string_view>

#include <zlib.h>

namespace hanzo::fusion::io::mcap::format {

inline constexpr char kMagic[8] = {'\x89', 'M', 'C', 'A', 'P', '0', '\r', '\n'};
inline constexpr std::size_t kMagicSize = 8;
inline constexpr std::size_t kRecordPrefixSize = 9;  // opcode + uint64 length
inline constexpr std::size_t kFooterContentSize = 20;
// Footer record + trailing magic.
inline constexpr std::size_t kFooterTailSize = kRecordPrefixSize + kFooterContentSize + kMagicSize;

enum Opcode : uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kAttachment = 0x09,
  kAttachmentIndex = 0x0A,
  kStatistics = 0x0B,
  kMetadata = 0x0C,
  kMetadataIndex = 0x0D,
  kSummaryOffset = 0x0E,
  kDataEnd = 0x0F,
};

inline uint32_t crc32_update(uint32_t crc, std::string_view bytes) {
  // zlib's crc32 takes uInt lengths; feed large buffers in pieces.
  while (!bytes.empty()) {
    const std::size_t n = std::min<std::size_t>(bytes.size(), 1u << 30);
    crc = static_cast<uint32_t>(::crc32(crc, reinterpret_cast<const Bytef*>(bytes.data()), static_cast<uInt>(n)));
    bytes.remove_prefix(n);
  }
  return crc;
}
inline uint32_t crc32_of(std::string_view bytes) { return crc32_update(0, bytes); }

/// Appends MCAP primitives to a string.
class ByteWriter {
 public:
  explicit ByteWriter(std::string& out) : out_(out) {}
  template <typename T>
  void integer(T value) {
    char bytes[sizeof(T)];
    for (std::size_t i = 0; i < sizeof(T); ++i) bytes[i] = static_cast<char>((static_cast<uint64_t>(value) >> (8 * i)) & 0xFF);
    out_.append(bytes, sizeof(T));
  }
  void u8(uint8_t v) { integer(v); }
  void u16(uint16_t v) { integer(v); }
  void u32(uint32_t v) { integer(v); }
  void u64(uint64_t v) { integer(v); }
  void string(std::string_view s) {
    u32(static_cast<uint32_t>(s.size()));
    out_.append(s);
  }
  void bytes32(std::string_view s) { string(s); }
  void string_map(const std::map<std::string, std::string>& map) {
    std::string body;
    ByteWriter inner(body);
    for (const auto& [key, value] : map) {
      inner.string(key);
      inner.string(value);
    }
    string(body);
  }
  void id_count_map(const std::map<uint16_t, uint64_t>& map) {
    u32(static_cast<uint32_t>(map.size() * 10));
    for (const auto& [key, value] : map) {
      u16(key);
      u64(value);
    }
  }
  void raw(std::string_view s) { out_.append(s); }

 private:
  std::string& out_;
};

/// A whole record: opcode, content length, content.
inline std::string record(uint8_t opcode, std::string_view content) {
  std::string out;
  out.reserve(kRecordPrefixSize + content.size());
  ByteWriter w(out);
  w.u8(opcode);
  w.u64(content.size());
  w.raw(content);
  return out;
}

/// Bounds-checked reads of MCAP primitives; after a failed read ok() is false and every later
/// read returns zero values.
class ByteReader {
 public:
  explicit ByteReader(std::string_view data) : data_(data) {}
  bool ok() const { return ok_; }
  std::size_t position() const { return position_; }
  std::size_t remaining() const { return ok_ ? data_.size() - position_ : 0; }

  template <typename T>
  T integer() {
    if (!take(sizeof(T))) return 0;
    uint64_t value = 0;
    for (std::size_t i = 0; i < sizeof(T); ++i) {
      value |= static_cast<uint64_t>(static_cast<unsigned char>(data_[position_ - sizeof(T) + i])) << (8 * i);
    }
    return static_cast<T>(value);
  }
  uint8_t u8() { return integer<uint8_t>(); }
  uint16_t u16() { return integer<uint16_t>(); }
  uint32_t u32() { return integer<uint32_t>(); }
  uint64_t u64() { return integer<uint64_t>(); }
  std::string_view bytes(uint64_t n) {
    if (!take(n)) return {};
    return data_.substr(position_ - n, n);
  }
  std::string_view string() { return bytes(u32()); }
  std::string_view rest() { return bytes(remaining()); }
  std::map<std::string, std::string> string_map() {
    std::map<std::string, std::string> map;
    ByteReader inner(bytes(u32()));
    while (ok_ && inner.ok() && inner.remaining() > 0) {
      std::string key(inner.string());
      std::string value(inner.string());
      if (inner.ok()) map.emplace(std::move(key), std::move(value));
    }
    if (!inner.ok()) ok_ = false;
    return map;
  }
  std::map<uint16_t, uint64_t> id_count_map() {
    std::map<uint16_t, uint64_t> map;
    ByteReader inner(bytes(u32()));
    while (ok_ && inner.ok() && inner.remaining() > 0) {
      const uint16_t key = inner.u16();
      const uint64_t value = inner.u64();
      if (inner.ok()) map[key] = value;
    }
    if (!inner.ok()) ok_ = false;
    return map;
  }

 private:
  bool take(uint64_t n) {
    if (!ok_ || n > data_.size() - position_) {
      ok_ = false;
      return false;
    }
    position_ += n;
    return true;
  }
  std::string_view data_;
  std::size_t position_ = 0;
  bool ok_ = true;
};

}  // namespace hanzo::fusion::io::mcap::format
