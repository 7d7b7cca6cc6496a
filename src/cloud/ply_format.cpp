// PLY files (Turk 1994; http://paulbourke.net/dataformats/ply/): a text header of elements and
// their properties, then the elements in order as ascii lines or binary records. Points are
// the "vertex" element; elements before it must have fixed-size records (no lists) in binary
// files, elements after it (faces) are ignored.

#include <cstring>
#include <sstream>

#include <fmt/format.h>

#include "raw_cloud.hpp"

namespace hanzo::fusion::cloud {
namespace {

struct PlyProperty {
  std::string name;
  ScalarType type = ScalarType::kFloat32;
  bool is_list = false;
};

struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProperty> properties;
};

Result<ScalarType> ply_type(const std::string& name) {
  if (name == "char" || name == "int8") return ScalarType::kInt8;
  if (name == "uchar" || name == "uint8") return ScalarType::kUint8;
  if (name == "short" || name == "int16") return ScalarType::kInt16;
  if (name == "ushort" || name == "uint16") return ScalarType::kUint16;
  if (name == "int" || name == "int32") return ScalarType::kInt32;
  if (name == "uint" || name == "uint32") return ScalarType::kUint32;
  if (name == "float" || name == "float32") return ScalarType::kFloat32;
  if (name == "double" || name == "float64") return ScalarType::kFloat64;
  return Error(fmt::format("unknown PLY property type '{}'", name));
}

const char* ply_type_name(ScalarType type) {
  switch (type) {
    case ScalarType::kInt8: return "char";
    case ScalarType::kUint8: return "uchar";
    case ScalarType::kInt16: return "short";
    case ScalarType::kUint16: return "ushort";
    case ScalarType::kInt32: return "int";
    case ScalarType::kUint32: return "uint";
    case ScalarType::kFloat64: return "double";
    default: return "float";
  }
}


}  // namespace

Result<RawCloud> parse_ply(const std::string& bytes) {
  if (bytes.compare(0, 4, "ply\n") != 0 && bytes.compare(0, 5, "ply\r\n") != 0) return Error("not a PLY file (no 'ply' magic line)");
  std::string format;
  std::vector<PlyElement> elements;
  size_t position = 0;
  for (int line_number = 1;; ++line_number) {
    if (position >= bytes.size() || line_number > 1000) return Error("the PLY header has no end_header line");
    const size_t end = std::min(bytes.find('\n', position), bytes.size());
    std::istringstream line(bytes.substr(position, end - position));
    position = end + 1;
    std::string key;
    line >> key;
    if (key == "end_header") break;
    if (key == "format") {
      line >> format;
    } else if (key == "element") {
      PlyElement element;
      long long count = -1;
      line >> element.name >> count;
      if (!line || count < 0) return Error(fmt::format("PLY header line {}: bad element line", line_number));
      element.count = static_cast<size_t>(count);
      elements.push_back(element);
    } else if (key == "property") {
      if (elements.empty()) return Error(fmt::format("PLY header line {}: property before any element", line_number));
      std::string type;
      line >> type;
      PlyProperty property;
      if (type == "list") {
        std::string count_type, item_type;
        line >> count_type >> item_type >> property.name;
        property.is_list = true;
      } else {
        HANZO_ASSIGN_OR_RETURN(property.type, ply_type(type));
        line >> property.name;
      }
      elements.back().properties.push_back(property);
    } else if (key != "comment" && key != "obj_info" && key != "ply" && !key.empty()) {
      return Error(fmt::format("PLY header line {}: unexpected '{}'", line_number, key));
    }
  }
  const bool ascii = format == "ascii";
  const bool big_endian = format == "binary_big_endian";
  if (!ascii && !big_endian && format != "binary_little_endian") return Error(fmt::format("unknown PLY format '{}'", format));

  size_t skip_bytes = 0;   // binary: bytes of the elements before the vertices
  size_t skip_lines = 0;   // ascii: lines of those elements
  const PlyElement* vertex = nullptr;
  for (const PlyElement& element : elements) {
    if (element.name == "vertex") {
      vertex = &element;
      break;
    }
    skip_lines += element.count;
    for (const PlyProperty& property : element.properties) {
      if (property.is_list && !ascii) return Error(fmt::format("PLY element '{}' before the vertices has list properties", element.name));
      skip_bytes += element.count * scalar_size(property.type);
    }
  }
  if (!vertex) return Error("the PLY file has no vertex element");
  if (vertex->count > (size_t{1} << 32)) return Error(fmt::format("PLY vertex count {} is beyond 2^32", vertex->count));

  RawCloud raw;
  for (const PlyProperty& property : vertex->properties) {
    if (property.is_list) return Error(fmt::format("PLY vertex property '{}' is a list", property.name));
    raw.add_field(property.name, property.type);
  }
  raw.count = vertex->count;
  const size_t data_size = raw.count * raw.record_size;
  if (!ascii) {
    const size_t start = position + skip_bytes;
    const size_t available = bytes.size() > start ? bytes.size() - start : 0;
    if (available < data_size) {
      return Error(fmt::format("PLY vertex data holds {} bytes, {} vertices x {} bytes needs {}", available, raw.count, raw.record_size, data_size));
    }
    raw.bytes.assign(bytes.begin() + static_cast<std::ptrdiff_t>(start), bytes.begin() + static_cast<std::ptrdiff_t>(start + data_size));
    if (big_endian) {
      for (size_t i = 0; i < raw.count; ++i) {
        for (const RawField& field : raw.fields) {
          uint8_t* at = raw.bytes.data() + i * raw.record_size + field.offset;
          std::reverse(at, at + scalar_size(field.type));
        }
      }
    }
    return raw;
  }
  for (size_t line = 0; line < skip_lines; ++line) {
    position = bytes.find('\n', position);
    if (position == std::string::npos) return Error("PLY ascii data ends before the vertices");
    ++position;
  }
  // Every ascii value takes at least two bytes (a digit and a separator): a count the file cannot
  // hold is refused before its memory is taken.
  const size_t remaining = bytes.size() > position ? bytes.size() - position : 0;
  if (raw.count > remaining / std::max<size_t>(1, 2 * raw.fields.size())) {
    return Error(fmt::format("PLY ascii data holds {} bytes, too few for the {} vertices the header declares", remaining, raw.count));
  }
  raw.bytes.resize(data_size);
  for (size_t i = 0; i < raw.count; ++i) {
    if (position >= bytes.size()) return Error(fmt::format("PLY ascii data holds {} of {} vertices", i, raw.count));
    const size_t end = std::min(bytes.find('\n', position), bytes.size());
    std::istringstream line(bytes.substr(position, end - position));
    position = end + 1;
    for (const RawField& field : raw.fields) {
      double value = 0.0;
      if (!(line >> value)) return Error(fmt::format("PLY ascii vertex {}: property '{}' is missing or not a number", i, field.name));
      store_scalar(field.type, value, raw.bytes.data() + i * raw.record_size + field.offset);
    }
  }
  return raw;
}

std::string format_ply(const RawCloud& raw) {
  std::string out = fmt::format("ply\nformat binary_little_endian 1.0\ncomment hanzo-fusion\nelement vertex {}\n", raw.count);
  for (const RawField& field : raw.fields) out += fmt::format("property {} {}\n", ply_type_name(field.type), field.name);
  out += "end_header\n";
  out.append(reinterpret_cast<const char*>(raw.bytes.data()), raw.bytes.size());
  return out;
}

}  // namespace hanzo::fusion::cloud
