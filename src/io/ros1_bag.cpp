#include "hanzo/fusion/io/ros1_bag.hpp"

#include <bzlib.h>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "mcap_compression.hpp"
#include "mcap_format.hpp"

namespace hanzo::fusion::io::ros1 {
namespace {

using mcap::format::ByteReader;

constexpr std::string_view kMagic = "#ROSBAG V2.0\n";
enum Op : uint8_t { kMessageData = 0x02, kBagHeader = 0x03, kIndexData = 0x04, kChunk = 0x05, kChunkInfo = 0x06, kConnection = 0x07 };

// "name=value" fields of a record header (or of a connection's data).
Result<std::map<std::string, std::string>> parse_fields(std::string_view bytes) {
  std::map<std::string, std::string> fields;
  ByteReader r(bytes);
  while (r.remaining() > 0) {
    const std::string_view field = r.string();
    if (!r.ok()) return Error("truncated header field");
    const auto equals = field.find('=');
    if (equals == std::string_view::npos) return Error(fmt::format("header field without '=' ({} bytes)", field.size()));
    fields.emplace(std::string(field.substr(0, equals)), std::string(field.substr(equals + 1)));
  }
  return fields;
}

template <typename T>
Result<T> field_as(const std::map<std::string, std::string>& fields, const std::string& name) {
  const auto it = fields.find(name);
  if (it == fields.end() || it->second.size() != sizeof(T)) return Error(fmt::format("header field '{}' missing or of wrong size", name));
  ByteReader r(it->second);
  return r.integer<T>();
}

Result<std::string> field_string(const std::map<std::string, std::string>& fields, const std::string& name) {
  const auto it = fields.find(name);
  if (it == fields.end()) return Error(fmt::format("header field '{}' missing", name));
  return it->second;
}

Result<std::string> decompress_chunk(const std::string& compression, std::string_view data, uint32_t size) {
  if (compression == "none") {
    if (data.size() != size) return Error(fmt::format("uncompressed chunk holds {} bytes, its header says {}", data.size(), size));
    return std::string(data);
  }
  if (compression == "bz2") {
    if (size > mcap::kMaxChunkBytes) return Error(fmt::format("chunk declares {} bytes uncompressed, more than {}", size, mcap::kMaxChunkBytes));
    std::string out(size, '\0');
    unsigned int out_size = size;
    const int status = BZ2_bzBuffToBuffDecompress(out.data(), &out_size, const_cast<char*>(data.data()),
                                                  static_cast<unsigned int>(data.size()), 0, 0);
    if (status != BZ_OK || out_size != size) return Error(fmt::format("bz2 chunk does not decompress (status {})", status));
    return out;
  }
  if (compression == "lz4") return mcap::decompress("lz4", data, size);  // roslz4 writes LZ4 frames
  return Error(fmt::format("unsupported chunk compression '{}' (expected none, bz2 or lz4)", compression));
}

// Walks the records of `bytes` (the file after the magic, or a chunk's records).
struct Walker {
  std::map<uint32_t, Connection>& connections;
  const std::function<Status(const BagMessage&)>* on_message;
  BagSummary& summary;

  Status connection(const std::map<std::string, std::string>& header, std::string_view data) {
    Connection c;
    HANZO_ASSIGN_OR_RETURN(c.id, field_as<uint32_t>(header, "conn"));
    HANZO_ASSIGN_OR_RETURN(c.topic, field_string(header, "topic"));
    std::map<std::string, std::string> info;
    HANZO_ASSIGN_OR_RETURN(info, parse_fields(data));
    c.type = info["type"];
    c.md5sum = info["md5sum"];
    c.message_definition = info["message_definition"];
    connections.emplace(c.id, std::move(c));
    return ok_status();
  }

  Status message(const std::map<std::string, std::string>& header, std::string_view data) {
    uint32_t id = 0;
    uint64_t time = 0;
    HANZO_ASSIGN_OR_RETURN(id, field_as<uint32_t>(header, "conn"));
    HANZO_ASSIGN_OR_RETURN(time, field_as<uint64_t>(header, "time"));
    const auto it = connections.find(id);
    if (it == connections.end()) return Error(fmt::format("message on connection {} before its definition", id));
    ++summary.messages;
    if (on_message == nullptr) return ok_status();
    BagMessage message{&it->second, {static_cast<uint32_t>(time & 0xFFFFFFFF), static_cast<uint32_t>(time >> 32)}, data};
    return (*on_message)(message);
  }

  // Returns the number of bytes consumed; a record cut off at the end sets complete = false.
  Status walk(std::string_view bytes, uint64_t base_offset, bool inside_chunk) {
    ByteReader r(bytes);
    while (r.remaining() > 0) {
      const uint64_t offset = base_offset + r.position();
      const std::string_view header_bytes = r.string();
      const std::string_view data = r.string();
      if (!r.ok()) {
        if (inside_chunk) return Error(fmt::format("record at byte {} runs past the end of its chunk", offset));
        summary.complete = false;
        return ok_status();
      }
      auto header = parse_fields(header_bytes);
      if (!header) return Error(fmt::format("record at byte {}: {}", offset, header.error().message));
      auto op = field_as<uint8_t>(*header, "op");
      if (!op) return Error(fmt::format("record at byte {}: {}", offset, op.error().message));
      Status status = ok_status();
      switch (*op) {
        case kConnection: status = connection(*header, data); break;
        case kMessageData: status = message(*header, data); break;
        case kChunk: {
          if (inside_chunk) return Error(fmt::format("chunk inside a chunk at byte {}", offset));
          auto compression = field_string(*header, "compression");
          auto size = field_as<uint32_t>(*header, "size");
          if (!compression || !size) return Error(fmt::format("chunk at byte {}: missing compression or size", offset));
          auto records = decompress_chunk(*compression, data, *size);
          if (!records) return Error(fmt::format("chunk at byte {}: {}", offset, records.error().message));
          ++summary.chunks;
          ++summary.chunk_compressions[*compression];
          status = walk(*records, 0, true);
          break;
        }
        case kBagHeader:
        case kIndexData:
        case kChunkInfo:
          break;
        default:
          logger()->debug("bag record at byte {}: unknown op {:#04x} skipped", offset, *op);
      }
      if (!status) {
        return inside_chunk ? status : Error(fmt::format("record at byte {}: {}", offset, status.error().message));
      }
    }
    return ok_status();
  }
};

Result<BagSummary> walk_file(const std::string& path, std::map<uint32_t, Connection>& connections,
                             const std::function<Status(const BagMessage&)>* on_message) {
  // Records are walked from a memory copy of the file region by region: chunks are read one at
  // a time so memory stays at one chunk.
  std::ifstream file(path, std::ios::binary);
  if (!file) return Error(fmt::format("{}: cannot open file ({})", path, std::strerror(errno)));
  std::string magic(kMagic.size(), '\0');
  file.read(magic.data(), static_cast<std::streamsize>(magic.size()));
  if (!file || magic != kMagic) {
    if (magic.rfind("#ROSBAG V", 0) == 0) {
      return Error(fmt::format("{}: unsupported bag version '{}' (only 2.0 is read)", path, magic.substr(9, 3)));
    }
    return Error(fmt::format("{}: not a ROS bag (bad magic line)", path));
  }
  std::error_code size_error;
  const uint64_t file_size = std::filesystem::file_size(path, size_error);
  BagSummary summary;
  Walker walker{connections, on_message, summary};
  uint64_t offset = kMagic.size();
  while (true) {
    // One top-level record at a time: lengths first, then its bytes.
    char length_bytes[4];
    std::string record;
    auto read_block = [&](std::string& into) -> bool {
      if (!file.read(length_bytes, 4)) return false;
      ByteReader r(std::string_view(length_bytes, 4));
      const uint32_t length = r.u32();
      // A length past the end of the file is a cut-off (or corrupted) record: never allocate it.
      if (!size_error && offset + into.size() + 4 + length > file_size) return false;
      into.append(length_bytes, 4);
      const std::size_t before = into.size();
      into.resize(before + length);
      return static_cast<bool>(file.read(into.data() + before, length));
    };
    if (!read_block(record)) {
      if (file.gcount() != 0 || !record.empty()) summary.complete = false;
      break;
    }
    if (!read_block(record)) {
      summary.complete = false;
      break;
    }
    HANZO_RETURN_IF_ERROR(with_context(Result<void>(walker.walk(record, offset, false)), path));
    offset += record.size();
  }
  if (!summary.complete) logger()->warn("{}: bag ends inside a record (cut-off recording); read up to byte {}", path, offset);
  return summary;
}

}  // namespace

Result<BagSummary> read_bag(const std::string& path, const std::function<Status(const BagMessage&)>& on_message) {
  std::map<uint32_t, Connection> connections;
  return walk_file(path, connections, &on_message);
}

Result<std::map<uint32_t, Connection>> read_bag_connections(const std::string& path) {
  std::map<uint32_t, Connection> connections;
  HANZO_RETURN_IF_ERROR(walk_file(path, connections, nullptr));
  return connections;
}

}  // namespace hanzo::fusion::io::ros1
