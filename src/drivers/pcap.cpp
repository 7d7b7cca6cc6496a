#include "hanzo/fusion/drivers/pcap.hpp"

#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>

#include <fmt/format.h>

namespace hanzo::fusion::drivers {

namespace {

constexpr uint32_t kMaxRecordBytes = 1u << 26;  // 64 MiB: more is a corrupt length field
constexpr uint32_t kPcapngSection = 0x0A0D0D0A;
constexpr uint32_t kPcapngByteOrder = 0x1A2B3C4D;
constexpr std::size_t kMaxPendingFragments = 256;

uint16_t read16(const std::string& data, std::size_t at, bool swapped) {
  uint16_t value = 0;
  std::memcpy(&value, data.data() + at, 2);
  return swapped ? static_cast<uint16_t>((value >> 8) | (value << 8)) : value;
}
uint32_t read32(const std::string& data, std::size_t at, bool swapped) {
  uint32_t value = 0;
  std::memcpy(&value, data.data() + at, 4);
  return swapped ? __builtin_bswap32(value) : value;
}
uint16_t big16(const std::string& data, std::size_t at) {
  return static_cast<uint16_t>((static_cast<uint8_t>(data[at]) << 8) | static_cast<uint8_t>(data[at + 1]));
}

// Reads up to `count` bytes into `out`, growing it as data arrives (a corrupt length near the
// end of a file costs what the file holds, not what the length claims). The bytes read.
std::size_t read_up_to(std::istream& in, std::size_t count, std::string& out) {
  constexpr std::size_t kChunk = 1 << 20;
  out.clear();
  while (out.size() < count) {
    const std::size_t before = out.size();
    const std::size_t want = std::min(kChunk, count - before);
    out.resize(before + want);
    in.read(out.data() + before, static_cast<std::streamsize>(want));
    const auto got = static_cast<std::size_t>(in.gcount());
    out.resize(before + got);
    if (got < want) break;
  }
  return out.size();
}

Timestamp time_of(uint64_t units, double seconds_per_unit) {
  // Integer arithmetic for the usual decimal resolutions (microseconds, nanoseconds).
  if (seconds_per_unit == 1e-6) return Timestamp::from_nanoseconds(static_cast<int64_t>(units) * 1000);
  if (seconds_per_unit == 1e-9) return Timestamp::from_nanoseconds(static_cast<int64_t>(units));
  return Timestamp::from_nanoseconds(static_cast<int64_t>(std::llround(static_cast<long double>(units) * seconds_per_unit * 1e9L)));
}

}  // namespace

Result<PcapReader> PcapReader::open(const std::string& path) {
  PcapReader reader;
  reader.path_ = path;
  reader.file_ = std::make_unique<std::ifstream>(path, std::ios::binary);
  if (!*reader.file_) return Error(fmt::format("{}: cannot open file", path));
  return start(std::move(reader));
}

Result<PcapReader> PcapReader::from_bytes(std::string bytes, const std::string& name) {
  PcapReader reader;
  reader.path_ = name;
  reader.file_ = std::make_unique<std::istringstream>(std::move(bytes), std::ios::binary);
  return start(std::move(reader));
}

Result<PcapReader> PcapReader::start(PcapReader reader) {
  const std::string& path = reader.path_;
  std::string header(24, '\0');
  if (!reader.file_->read(header.data(), 24)) return Error(fmt::format("{}: not a packet capture (shorter than a pcap header)", path));
  const uint32_t magic = read32(header, 0, false);
  if (magic == kPcapngSection) {
    reader.pcapng_ = true;
    reader.file_->seekg(0);
    return reader;
  }
  if (magic == 0xa1b2c3d4 || magic == 0xa1b23c4d) {
    reader.swapped_ = false;
  } else if (magic == 0xd4c3b2a1 || magic == 0x4d3cb2a1) {
    reader.swapped_ = true;
  } else {
    return Error(fmt::format("{}: not a packet capture (magic {:08x}: neither pcap nor pcapng)", path, magic));
  }
  const uint32_t native_magic = reader.swapped_ ? __builtin_bswap32(magic) : magic;
  reader.classic_seconds_per_unit_ = native_magic == 0xa1b23c4d ? 1e-9 : 1e-6;
  reader.classic_link_type_ = read32(header, 20, reader.swapped_) & 0x0fffffff;
  reader.offset_ = 24;
  return reader;
}

Result<std::optional<PcapReader::Record>> PcapReader::next_record() { return pcapng_ ? next_pcapng_record() : next_classic_record(); }

Result<std::optional<PcapReader::Record>> PcapReader::next_classic_record() {
  std::string header(16, '\0');
  file_->read(header.data(), 16);
  if (file_->gcount() == 0) return std::optional<Record>();
  if (file_->gcount() < 16) {
    ++statistics_.truncated;  // the capture stopped inside a record header
    return std::optional<Record>();
  }
  const uint32_t seconds = read32(header, 0, swapped_), fraction = read32(header, 4, swapped_);
  const uint32_t captured = read32(header, 8, swapped_);
  if (captured > kMaxRecordBytes) return Error(fmt::format("{}: record at byte {} claims {} bytes (corrupt)", path_, offset_, captured));
  Record record;
  record.link_type = classic_link_type_;
  if (read_up_to(*file_, captured, record.data) < captured) {
    ++statistics_.truncated;  // the capture stopped inside the last record
    return std::optional<Record>();
  }
  const int64_t nanoseconds = classic_seconds_per_unit_ == 1e-9 ? static_cast<int64_t>(fraction) : static_cast<int64_t>(fraction) * 1000;
  record.time = Timestamp::from_nanoseconds(static_cast<int64_t>(seconds) * 1'000'000'000LL + nanoseconds);
  offset_ += 16 + captured;
  ++statistics_.records;
  return std::optional<Record>(std::move(record));
}

Result<std::optional<PcapReader::Record>> PcapReader::next_pcapng_record() {
  while (true) {
    std::string head(8, '\0');
    file_->read(head.data(), 8);
    if (file_->gcount() == 0) return std::optional<Record>();
    if (file_->gcount() < 8) {
      ++statistics_.truncated;
      return std::optional<Record>();
    }
    const uint32_t type = read32(head, 0, false);
    if (type == kPcapngSection) {  // a new section: its byte order, its interfaces
      std::string order(4, '\0');
      if (!file_->read(order.data(), 4)) return Error(fmt::format("{}: section header at byte {} cut short", path_, offset_));
      const uint32_t magic = read32(order, 0, false);
      if (magic == kPcapngByteOrder) {
        swapped_ = false;
      } else if (magic == __builtin_bswap32(kPcapngByteOrder)) {
        swapped_ = true;
      } else {
        return Error(fmt::format("{}: section header at byte {} has byte-order magic {:08x}", path_, offset_, magic));
      }
      interfaces_.clear();
      const uint32_t length = read32(head, 4, swapped_);
      if (length < 28 || length % 4 != 0 || length > kMaxRecordBytes) return Error(fmt::format("{}: section header at byte {} of length {}", path_, offset_, length));
      file_->seekg(static_cast<std::streamoff>(length - 12), std::ios::cur);
      offset_ += length;
      continue;
    }
    const uint32_t length = read32(head, 4, swapped_);
    if (length < 12 || length % 4 != 0 || length > kMaxRecordBytes) {
      return Error(fmt::format("{}: block at byte {} of length {} (corrupt)", path_, offset_, length));
    }
    std::string body;
    if (read_up_to(*file_, length - 8, body) < length - 8) {
      ++statistics_.truncated;
      return std::optional<Record>();
    }
    const uint64_t block_offset = offset_;
    offset_ += length;
    const std::size_t content = body.size() - 4;  // without the trailing length
    const bool swapped = swapped_;
    if (type == 1) {  // interface description
      if (content < 8) return Error(fmt::format("{}: interface block at byte {} cut short", path_, block_offset));
      Interface interface;
      interface.link_type = read16(body, 0, swapped);
      for (std::size_t at = 8; at + 4 <= content;) {
        const uint16_t code = read16(body, at, swapped), size = read16(body, at + 2, swapped);
        if (code == 0 || at + 4 + size > content) break;
        if (code == 9 && size >= 1) {  // if_tsresol
          const auto value = static_cast<uint8_t>(body[at + 4]);
          interface.seconds_per_unit = (value & 0x80) != 0 ? std::ldexp(1.0, -(value & 0x7f)) : std::pow(10.0, -static_cast<double>(value));
          if ((value & 0x80) == 0 && value == 6) interface.seconds_per_unit = 1e-6;
          if ((value & 0x80) == 0 && value == 9) interface.seconds_per_unit = 1e-9;
        }
        at += 4 + ((size + 3u) & ~3u);
      }
      interfaces_.push_back(interface);
      continue;
    }
    Record record;
    std::size_t data_at = 0, captured = 0;
    uint32_t interface_id = 0;
    uint64_t units = 0;
    if (type == 6 || type == 2) {  // enhanced packet / obsolete packet
      if (content < 20) return Error(fmt::format("{}: packet block at byte {} cut short", path_, block_offset));
      interface_id = type == 6 ? read32(body, 0, swapped) : read16(body, 0, swapped);
      units = (static_cast<uint64_t>(read32(body, 4, swapped)) << 32) | read32(body, 8, swapped);
      captured = read32(body, 12, swapped);
      data_at = 20;
    } else if (type == 3) {  // simple packet: no time, interface 0
      if (content < 4) return Error(fmt::format("{}: packet block at byte {} cut short", path_, block_offset));
      captured = std::min<std::size_t>(read32(body, 0, swapped), content - 4);
      data_at = 4;
    } else {
      continue;  // statistics, name resolution, custom blocks
    }
    if (data_at + captured > content) return Error(fmt::format("{}: packet block at byte {} claims {} bytes of data", path_, block_offset, captured));
    if (interface_id >= interfaces_.size()) return Error(fmt::format("{}: packet block at byte {} names interface {} (not described)", path_, block_offset, interface_id));
    record.link_type = interfaces_[interface_id].link_type;
    record.time = time_of(units, interfaces_[interface_id].seconds_per_unit);
    record.data = body.substr(data_at, captured);
    ++statistics_.records;
    return std::optional<Record>(std::move(record));
  }
}

std::optional<UdpDatagram> PcapReader::datagram_of(const Record& record) {
  const std::string& frame = record.data;
  std::size_t ip = 0;
  switch (record.link_type) {
    case 1: {  // Ethernet, VLAN tags skipped
      if (frame.size() < 14) {
        ++statistics_.truncated;
        return std::nullopt;
      }
      std::size_t type_at = 12;
      while (type_at + 2 <= frame.size() && (big16(frame, type_at) == 0x8100 || big16(frame, type_at) == 0x88a8)) type_at += 4;
      if (type_at + 2 > frame.size()) {
        ++statistics_.truncated;
        return std::nullopt;
      }
      if (big16(frame, type_at) != 0x0800) {
        ++statistics_.other_packets;
        return std::nullopt;
      }
      ip = type_at + 2;
      break;
    }
    case 113:  // Linux cooked capture
      if (frame.size() < 16) {
        ++statistics_.truncated;
        return std::nullopt;
      }
      if (big16(frame, 14) != 0x0800) {
        ++statistics_.other_packets;
        return std::nullopt;
      }
      ip = 16;
      break;
    case 0:
    case 108:  // BSD loopback: a 4-byte address family, 2 = IPv4 in either byte order
      if (frame.size() < 4) {
        ++statistics_.truncated;
        return std::nullopt;
      }
      if (read32(frame, 0, false) != 2 && read32(frame, 0, true) != 2) {
        ++statistics_.other_packets;
        return std::nullopt;
      }
      ip = 4;
      break;
    case 12:
    case 14:
    case 101:  // raw IP
      ip = 0;
      break;
    default:
      ++statistics_.other_packets;
      return std::nullopt;
  }
  if (frame.size() < ip + 20) {
    ++statistics_.truncated;
    return std::nullopt;
  }
  const auto version_length = static_cast<uint8_t>(frame[ip]);
  if ((version_length >> 4) != 4) {
    ++statistics_.other_packets;  // IPv6 and anything else
    return std::nullopt;
  }
  const std::size_t header_length = 4u * (version_length & 0x0f);
  // Some firmware (early VLP-16 position packets) claims more IP bytes than it sends: the UDP
  // length then decides.
  const std::size_t total_length = std::min<std::size_t>(big16(frame, ip + 2), frame.size() - ip);
  const uint16_t identification = big16(frame, ip + 4), flags_offset = big16(frame, ip + 6);
  const auto protocol = static_cast<uint8_t>(frame[ip + 9]);
  if (protocol != 17) {
    ++statistics_.other_packets;
    return std::nullopt;
  }
  if (header_length < 20 || total_length < header_length) {
    ++statistics_.truncated;
    return std::nullopt;
  }
  std::array<uint8_t, 4> source{}, destination{};
  std::memcpy(source.data(), frame.data() + ip + 12, 4);
  std::memcpy(destination.data(), frame.data() + ip + 16, 4);
  std::string udp = frame.substr(ip + header_length, total_length - header_length);
  const bool more_fragments = (flags_offset & 0x2000) != 0;
  const uint32_t fragment_offset = 8u * (flags_offset & 0x1fff);
  if (more_fragments || fragment_offset > 0) {
    ++statistics_.fragments;
    uint32_t source_word = 0, destination_word = 0;
    std::memcpy(&source_word, source.data(), 4);
    std::memcpy(&destination_word, destination.data(), 4);
    const auto key = std::make_tuple(source_word, destination_word, identification);
    Fragments& pending = fragments_[key];
    pending.pieces[fragment_offset] = std::move(udp);
    if (!more_fragments) pending.total = fragment_offset + static_cast<uint32_t>(pending.pieces[fragment_offset].size());
    if (!pending.total) return std::nullopt;
    std::string assembled;
    for (const auto& [at, piece] : pending.pieces) {
      if (at != assembled.size()) return std::nullopt;  // a hole: more to come
      assembled += piece;
    }
    if (assembled.size() != *pending.total) return std::nullopt;
    fragments_.erase(key);
    udp = std::move(assembled);
    if (fragments_.size() > kMaxPendingFragments) {  // lost fragments: forget the oldest sets
      statistics_.incomplete += fragments_.size();
      fragments_.clear();
    }
  }
  if (udp.size() < 8) {
    ++statistics_.truncated;
    return std::nullopt;
  }
  const std::size_t udp_length = big16(udp, 4);
  if (udp_length < 8 || udp_length > udp.size()) {
    ++statistics_.truncated;
    return std::nullopt;
  }
  UdpDatagram datagram;
  datagram.time = record.time;
  datagram.source_address = source;
  datagram.destination_address = destination;
  datagram.source_port = big16(udp, 0);
  datagram.destination_port = big16(udp, 2);
  datagram.payload = udp.substr(8, udp_length - 8);
  ++statistics_.datagrams;
  return datagram;
}

Result<std::optional<UdpDatagram>> PcapReader::next() {
  while (true) {
    Result<std::optional<Record>> record = next_record();
    if (!record) return record.error();
    if (!*record) {
      statistics_.incomplete += fragments_.size();
      fragments_.clear();
      return std::optional<UdpDatagram>();
    }
    std::optional<UdpDatagram> datagram = datagram_of(**record);
    if (datagram) return datagram;
  }
}

}  // namespace hanzo::fusion::drivers
