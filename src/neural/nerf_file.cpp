// NeRF files: "HZNERF1\n", one JSON line with the configuration and the parameter groups'
// sizes, then those groups (float32, little-endian: the encoding's table, the density network's
// and the colour network's weights), the occupancy grid's values (float32) and its seen-cells mask
// (one byte a cell).

#include <cstring>
#include <fstream>
#include <sstream>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/neural/nerf_field.hpp"
#include "nerf_network.hpp"

namespace hanzo::fusion::neural {

namespace {

constexpr char kMagic[] = "HZNERF1\n";

void append_floats(std::string& out, const float* data, std::size_t count) { out.append(reinterpret_cast<const char*>(data), count * sizeof(float)); }

}  // namespace

std::string serialize_nerf(const NerfField& field) {
  const NerfFieldConfig& c = field.config();
  const NerfField::Network& network = field.network();
  nlohmann::json sizes = nlohmann::json::array();
  for (std::span<const float> group : network.parameters()) sizes.push_back(group.size());
  const nlohmann::json header = {
      {"levels", c.encoding.levels},
      {"features_per_level", c.encoding.features_per_level},
      {"log2_table_size", c.encoding.log2_table_size},
      {"base_resolution", c.encoding.base_resolution},
      {"finest_resolution", c.encoding.finest_resolution},
      {"hidden_width", c.hidden_width},
      {"steps_per_diagonal", c.steps_per_diagonal},
      {"occupancy_resolution", c.occupancy.resolution},
      {"min_optical_thickness", c.occupancy.min_optical_thickness},
      {"box_centre", {c.box_centre.x(), c.box_centre.y(), c.box_centre.z()}},
      {"box_half_size", c.box_half_size},
      {"near", c.near},
      {"parameter_sizes", sizes},
  };
  std::string out = kMagic + header.dump() + "\n";
  for (std::span<const float> group : network.parameters()) append_floats(out, group.data(), group.size());
  const OccupancyGrid& grid = field.occupancy();
  append_floats(out, grid.values().data(), grid.values().size());
  out.append(reinterpret_cast<const char*>(grid.seen().data()), grid.seen().size());
  return out;
}

Status save_nerf(const std::string& path, const NerfField& field) { return write_file_durably(path, serialize_nerf(field)); }

Result<NerfField> load_nerf(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  if (!file) return Error(fmt::format("{}: cannot open", path));
  std::stringstream buffer;
  buffer << file.rdbuf();
  return parse_nerf(buffer.str(), path);
}

Result<NerfField> parse_nerf(std::string_view data, const std::string& path) {
  const std::size_t magic = std::strlen(kMagic);
  if (data.compare(0, magic, kMagic) != 0) return Error(fmt::format("{}: not a NeRF file (no HZNERF1 header)", path));
  const std::size_t line_end = data.find('\n', magic);
  if (line_end == std::string::npos) return Error(fmt::format("{}: truncated header", path));
  NerfFieldConfig c;
  std::vector<std::size_t> sizes;
  try {
    const nlohmann::json header = nlohmann::json::parse(data.substr(magic, line_end - magic));
    c.encoding.levels = header.at("levels");
    c.encoding.features_per_level = header.at("features_per_level");
    c.encoding.log2_table_size = header.at("log2_table_size");
    c.encoding.base_resolution = header.at("base_resolution");
    c.encoding.finest_resolution = header.at("finest_resolution");
    c.hidden_width = header.at("hidden_width");
    c.steps_per_diagonal = header.at("steps_per_diagonal");
    c.occupancy.resolution = header.at("occupancy_resolution");
    c.occupancy.min_optical_thickness = header.at("min_optical_thickness");
    const auto& centre = header.at("box_centre");
    c.box_centre = Eigen::Vector3d(centre.at(0), centre.at(1), centre.at(2));
    c.box_half_size = header.at("box_half_size");
    c.near = header.at("near");
    sizes = header.at("parameter_sizes").get<std::vector<std::size_t>>();
  } catch (const nlohmann::json::exception& error) {
    return Error(fmt::format("{}: bad header ({})", path, error.what()));
  }
  Result<NerfField> field = NerfField::create(c);
  if (!field) return Error(fmt::format("{}: {}", path, field.error().message));
  NerfField::Network& network = field->network();
  std::vector<std::span<float>> parameters = network.parameters();
  if (sizes.size() != parameters.size()) return Error(fmt::format("{}: {} parameter groups, the configuration makes {}", path, sizes.size(), parameters.size()));
  std::size_t offset = line_end + 1;
  const auto read_floats = [&](float* target, std::size_t count) {
    if (data.size() - offset < count * sizeof(float)) return false;
    std::memcpy(target, data.data() + offset, count * sizeof(float));
    offset += count * sizeof(float);
    return true;
  };
  for (std::size_t i = 0; i < parameters.size(); ++i) {
    if (sizes[i] != parameters[i].size()) {
      return Error(fmt::format("{}: parameter group {} holds {} values, the configuration makes {}", path, i, sizes[i], parameters[i].size()));
    }
    if (!read_floats(parameters[i].data(), sizes[i])) return Error(fmt::format("{}: truncated in parameter group {}", path, i));
  }
  OccupancyGrid& grid = field->occupancy();
  std::vector<float> values(grid.cells());
  if (!read_floats(values.data(), values.size())) return Error(fmt::format("{}: truncated in the occupancy grid", path));
  if (data.size() - offset != grid.cells()) return Error(fmt::format("{}: {} bytes after the occupancy values, expected {}", path, data.size() - offset, grid.cells()));
  std::vector<uint8_t> seen(data.begin() + static_cast<std::ptrdiff_t>(offset), data.end());  // (string_view iterators)
  grid.restore(std::move(values), std::move(seen));
  return field;
}

}  // namespace hanzo::fusion::neural
