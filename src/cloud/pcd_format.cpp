// PCD files (PCL's format, https://pointclouds.org/documentation/tutorials/pcd_file_format.html):
// a text header (VERSION, FIELDS, SIZE, TYPE, COUNT, WIDTH, HEIGHT, VIEWPOINT, POINTS, DATA)
// then the points as ascii lines, point-major binary records, or binary_compressed: uint32
// compressed size, uint32 uncompressed size, then LZF-compressed field-major data.

#include <charconv>
#include <cstring>
#include <sstream>

#include <fmt/format.h>
#include <pcl/io/lzf.h>

#include "raw_cloud.hpp"

namespace hanzo::fusion::cloud {
namespace {

struct PcdField {
  std::string name;
  char type = 'F';
  size_t size = 4;
  size_t count = 1;
};

Result<ScalarType> scalar_type(char type, size_t size) {
  if (type == 'F' && size == 4) return ScalarType::kFloat32;
  if (type == 'F' && size == 8) return ScalarType::kFloat64;
  if (type == 'I' || type == 'U') {
    const bool is_signed = type == 'I';
    switch (size) {
      case 1: return is_signed ? ScalarType::kInt8 : ScalarType::kUint8;
      case 2: return is_signed ? ScalarType::kInt16 : ScalarType::kUint16;
      case 4: return is_signed ? ScalarType::kInt32 : ScalarType::kUint32;
      case 8: return is_signed ? ScalarType::kInt64 : ScalarType::kUint64;
      default: break;
    }
  }
  return Error(fmt::format("unsupported field type {}{}", type, size));
}

std::vector<std::string> split(const std::string& line) {
  std::istringstream stream(line);
  std::vector<std::string> tokens;
  for (std::string token; stream >> token;) tokens.push_back(token);
  return tokens;
}

Result<size_t> parse_count(const std::string& token, const char* what) {
  size_t value = 0;
  const auto [end, error] = std::from_chars(token.data(), token.data() + token.size(), value);
  if (error != std::errc() || end != token.data() + token.size()) {
    return Error(fmt::format("{}: '{}' is not a non-negative integer", what, token));
  }
  return value;
}


}  // namespace

Result<RawCloud> parse_pcd(const std::string& bytes) {
  std::vector<PcdField> fields;
  size_t width = 0, height = 1, points = 0;
  bool have_points = false, have_width = false;
  std::string data_format;
  size_t position = 0;
  int line_number = 0;
  while (data_format.empty()) {
    if (position >= bytes.size()) return Error("the PCD header has no DATA line");
    const size_t end = std::min(bytes.find('\n', position), bytes.size());
    std::string line = bytes.substr(position, end - position);
    position = end + 1;
    ++line_number;
    if (line_number > 64) return Error("no PCD header (no DATA line in the first 64 lines)");
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const std::vector<std::string> tokens = split(line);
    if (tokens.empty() || tokens[0][0] == '#') continue;
    const std::string& key = tokens[0];
    const size_t values = tokens.size() - 1;
    const auto per_field = [&](const char* what) -> Status {
      if (values != fields.size()) {
        return Error(fmt::format("PCD header line {}: {} has {} values for {} fields", line_number, what, values, fields.size()));
      }
      return ok_status();
    };
    if (key == "VERSION" || key == "VIEWPOINT") continue;
    if (key == "FIELDS" || key == "COLUMNS") {
      fields.assign(values, PcdField{});
      for (size_t i = 0; i < values; ++i) fields[i].name = tokens[i + 1];
    } else if (key == "SIZE") {
      HANZO_RETURN_IF_ERROR(per_field("SIZE"));
      for (size_t i = 0; i < values; ++i) HANZO_ASSIGN_OR_RETURN(fields[i].size, parse_count(tokens[i + 1], "PCD SIZE"));
    } else if (key == "TYPE") {
      HANZO_RETURN_IF_ERROR(per_field("TYPE"));
      for (size_t i = 0; i < values; ++i) fields[i].type = tokens[i + 1].size() == 1 ? tokens[i + 1][0] : '?';
    } else if (key == "COUNT") {
      HANZO_RETURN_IF_ERROR(per_field("COUNT"));
      for (size_t i = 0; i < values; ++i) HANZO_ASSIGN_OR_RETURN(fields[i].count, parse_count(tokens[i + 1], "PCD COUNT"));
    } else if (key == "WIDTH" && values == 1) {
      HANZO_ASSIGN_OR_RETURN(width, parse_count(tokens[1], "PCD WIDTH"));
      have_width = true;
    } else if (key == "HEIGHT" && values == 1) {
      HANZO_ASSIGN_OR_RETURN(height, parse_count(tokens[1], "PCD HEIGHT"));
    } else if (key == "POINTS" && values == 1) {
      HANZO_ASSIGN_OR_RETURN(points, parse_count(tokens[1], "PCD POINTS"));
      have_points = true;
    } else if (key == "DATA" && values == 1) {
      data_format = tokens[1];
    } else {
      return Error(fmt::format("PCD header line {}: unexpected '{}'", line_number, line.substr(0, 40)));
    }
  }
  if (fields.empty()) return Error("the PCD header has no FIELDS");
  if (!have_points) {
    if (!have_width) return Error("the PCD header has neither POINTS nor WIDTH");
    points = width * height;
  }
  if (points > (size_t{1} << 32)) return Error(fmt::format("PCD POINTS {} is beyond 2^32", points));

  // The file's record layout; named scalar fields become RawFields (the first element of
  // multi-count fields, none of the padding fields "_").
  RawCloud raw;
  std::vector<ScalarType> types;
  std::vector<size_t> offsets;
  for (const PcdField& field : fields) {
    ScalarType type = ScalarType::kFloat32;
    HANZO_ASSIGN_OR_RETURN(type, scalar_type(field.type, field.size));
    if (field.count == 0 || field.count > 4096) return Error(fmt::format("PCD field '{}': COUNT {}", field.name, field.count));
    types.push_back(type);
    offsets.push_back(raw.record_size);
    if (field.name != "_") raw.fields.push_back({field.name, type, raw.record_size});
    raw.record_size += field.size * field.count;
  }
  raw.count = points;
  const size_t data_size = points * raw.record_size;
  const size_t available = bytes.size() - std::min(position, bytes.size());

  if (data_format == "binary") {
    if (available < data_size) {
      return Error(fmt::format("PCD binary data holds {} bytes, POINTS {} x {} bytes needs {}", available, points, raw.record_size, data_size));
    }
    raw.bytes.assign(bytes.begin() + static_cast<std::ptrdiff_t>(position), bytes.begin() + static_cast<std::ptrdiff_t>(position + data_size));
    return raw;
  }
  if (data_format == "binary_compressed") {
    if (available < 8) return Error("PCD binary_compressed data has no size words");
    uint32_t compressed = 0, uncompressed = 0;
    std::memcpy(&compressed, bytes.data() + position, 4);
    std::memcpy(&uncompressed, bytes.data() + position + 4, 4);
    if (compressed > available - 8) return Error(fmt::format("PCD binary_compressed: {} compressed bytes announced, {} present", compressed, available - 8));
    if (uncompressed != data_size) {
      return Error(fmt::format("PCD binary_compressed: {} uncompressed bytes announced, POINTS {} x {} bytes is {}", uncompressed, points, raw.record_size, data_size));
    }
    if (data_size > 200 * static_cast<size_t>(compressed) + 4096) return Error("PCD binary_compressed: implausible compression ratio");
    std::vector<uint8_t> field_major(data_size);
    if (data_size > 0 && pcl::lzfDecompress(bytes.data() + position + 8, compressed, field_major.data(), uncompressed) != uncompressed) {
      return Error("PCD binary_compressed: the LZF data is corrupt");
    }
    raw.bytes.resize(data_size);
    size_t source = 0;
    for (size_t f = 0; f < fields.size(); ++f) {
      const size_t field_bytes = fields[f].size * fields[f].count;
      for (size_t i = 0; i < points; ++i, source += field_bytes) {
        std::memcpy(raw.bytes.data() + i * raw.record_size + offsets[f], field_major.data() + source, field_bytes);
      }
    }
    return raw;
  }
  if (data_format != "ascii") return Error(fmt::format("PCD DATA '{}' is not ascii, binary or binary_compressed", data_format));

  raw.bytes.reserve(std::min(data_size, available * 8));
  std::vector<uint8_t> record(raw.record_size);
  size_t read_points = 0;
  while (position < bytes.size() && read_points < points) {
    const size_t end = std::min(bytes.find('\n', position), bytes.size());
    const std::vector<std::string> tokens = split(bytes.substr(position, end - position));
    position = end + 1;
    if (tokens.empty()) continue;
    size_t token = 0;
    for (size_t f = 0; f < fields.size(); ++f) {
      for (size_t c = 0; c < fields[f].count; ++c, ++token) {
        if (token >= tokens.size()) return Error(fmt::format("PCD ascii point {}: {} values, the fields need more", read_points, tokens.size()));
        char* parsed_end = nullptr;
        const double value = std::strtod(tokens[token].c_str(), &parsed_end);
        if (*parsed_end != '\0') return Error(fmt::format("PCD ascii point {}: '{}' is not a number", read_points, tokens[token]));
        store_scalar(types[f], value, record.data() + offsets[f] + c * fields[f].size);
      }
    }
    raw.bytes.insert(raw.bytes.end(), record.begin(), record.end());
    ++read_points;
  }
  if (read_points < points) return Error(fmt::format("PCD ascii data holds {} points, POINTS says {}", read_points, points));
  return raw;
}

std::string format_pcd(const RawCloud& raw) {
  std::string names, sizes, types, counts;
  for (const RawField& field : raw.fields) {
    names += " " + field.name;
    sizes += fmt::format(" {}", scalar_size(field.type));
    types += field.type == ScalarType::kFloat32 || field.type == ScalarType::kFloat64 ? " F"
             : (field.type == ScalarType::kInt8 || field.type == ScalarType::kInt16 || field.type == ScalarType::kInt32 ||
                field.type == ScalarType::kInt64) ? " I" : " U";
    counts += " 1";
  }
  std::string out = fmt::format(
      "# .PCD v0.7 - Point Cloud Data file format (hanzo-fusion)\nVERSION 0.7\nFIELDS{}\nSIZE{}\nTYPE{}\nCOUNT{}\n"
      "WIDTH {}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {}\nDATA binary\n",
      names, sizes, types, counts, raw.count, raw.count);
  out.append(reinterpret_cast<const char*>(raw.bytes.data()), raw.bytes.size());
  return out;
}

}  // namespace hanzo::fusion::cloud
