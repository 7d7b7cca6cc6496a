#include "hanzo/fusion/maps/splat_ply.hpp"

#include <cmath>
#include <cstring>
#include <map>
#include <sstream>
#include <tuple>

#include <fmt/format.h>

namespace hanzo::fusion::maps {

namespace {

constexpr uint32_t kMaxShDegree = 3;

/// Coefficients per channel of degree `degree`: (degree + 1)^2.
constexpr int coefficients_of(uint32_t degree) { return static_cast<int>((degree + 1) * (degree + 1)); }

std::vector<std::string> property_names(uint32_t sh_degree) {
  std::vector<std::string> names = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"};
  for (int i = 0; i < 3 * (coefficients_of(sh_degree) - 1); ++i) names.push_back(fmt::format("f_rest_{}", i));
  for (const char* name : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"}) names.emplace_back(name);
  return names;
}

}  // namespace

Status validate_splats(const msgs::GaussianSplatLayer& layer) {
  if (layer.sh_degree > kMaxShDegree) return Error(fmt::format("gaussian_splats: sh_degree {} (expected 0 to {})", layer.sh_degree, kMaxShDegree));
  const std::size_t n = layer.opacity_logits.size();
  const std::size_t sh_floats = 3 * static_cast<std::size_t>(coefficients_of(layer.sh_degree));
  for (const auto& [values, width, name] : {std::tuple{&layer.positions, std::size_t{3}, "positions"}, std::tuple{&layer.log_scales, std::size_t{3}, "log_scales"},
                                            std::tuple{&layer.rotations, std::size_t{4}, "rotations"}, std::tuple{&layer.opacity_logits, std::size_t{1}, "opacity_logits"},
                                            std::tuple{&layer.sh, sh_floats, "sh"}}) {
    if (values->size() != n * width) {
      return Error(fmt::format("gaussian_splats: {} holds {} floats, {} Gaussians need {}", name, values->size(), n, n * width));
    }
    for (const float value : *values) {
      if (!std::isfinite(value)) return Error(fmt::format("gaussian_splats: {} holds a value that is not finite", name));
    }
  }
  return ok_status();
}

std::string encode_splat_ply(const msgs::GaussianSplatLayer& layer) {
  const std::vector<std::string> names = property_names(layer.sh_degree);
  const std::size_t count = layer.opacity_logits.size();
  std::string out = fmt::format("ply\nformat binary_little_endian 1.0\nelement vertex {}\n", count);
  for (const std::string& name : names) out += "property float " + name + "\n";
  out += "end_header\n";
  const int coefficients = coefficients_of(layer.sh_degree);
  const std::size_t sh_floats = 3 * static_cast<std::size_t>(coefficients);
  std::vector<float> row(names.size());
  out.reserve(out.size() + count * row.size() * sizeof(float));
  for (std::size_t i = 0; i < count; ++i) {
    std::size_t j = 0;
    for (std::size_t a = 0; a < 3; ++a) row[j++] = layer.positions[3 * i + a];
    for (int a = 0; a < 3; ++a) row[j++] = 0.0f;
    const float* sh = &layer.sh[i * sh_floats];
    for (int c = 0; c < 3; ++c) row[j++] = sh[c];
    for (int c = 0; c < 3; ++c) {
      for (int k = 1; k < coefficients; ++k) row[j++] = sh[3 * k + c];
    }
    row[j++] = layer.opacity_logits[i];
    for (std::size_t a = 0; a < 3; ++a) row[j++] = layer.log_scales[3 * i + a];
    for (std::size_t a = 0; a < 4; ++a) row[j++] = layer.rotations[4 * i + a];
    out.append(reinterpret_cast<const char*>(row.data()), row.size() * sizeof(float));
  }
  return out;
}

Result<msgs::GaussianSplatLayer> decode_splat_ply(std::string_view bytes, const std::string& source) {
  const std::size_t header_end = bytes.find("end_header\n");
  if (!bytes.starts_with("ply\n") || header_end == std::string_view::npos) return Error(fmt::format("{}: not a PLY file", source));
  std::istringstream header{std::string(bytes.substr(0, header_end))};
  std::string line;
  std::size_t count = 0;
  bool binary = false;
  std::map<std::string, std::size_t> columns;
  std::size_t column = 0;
  while (std::getline(header, line)) {
    std::istringstream words(line);
    std::string word;
    words >> word;
    if (word == "format") {
      std::string format;
      words >> format;
      binary = format == "binary_little_endian";
    } else if (word == "element") {
      std::string name;
      words >> name >> count;
      if (name != "vertex") return Error(fmt::format("{}: element '{}' (only vertices of Gaussians are read)", source, name));
    } else if (word == "property") {
      std::string type, name;
      words >> type >> name;
      if (type != "float") return Error(fmt::format("{}: property {} is {} (Gaussian PLYs hold floats)", source, name, type));
      columns[name] = column++;
    }
  }
  if (!binary) return Error(fmt::format("{}: not binary_little_endian", source));
  int rest = 0;
  while (columns.contains(fmt::format("f_rest_{}", rest))) ++rest;
  uint32_t degree = 0;
  while (degree <= kMaxShDegree && 3 * (coefficients_of(degree) - 1) != rest) ++degree;
  if (degree > kMaxShDegree) return Error(fmt::format("{}: {} f_rest properties fit no spherical-harmonics degree up to 3", source, rest));
  for (const std::string& name : property_names(degree)) {
    if (name[0] != 'n' && !columns.contains(name)) return Error(fmt::format("{}: no property '{}'", source, name));
  }
  const std::size_t body = header_end + std::strlen("end_header\n");
  if (bytes.size() - body != count * column * sizeof(float)) {
    return Error(fmt::format("{}: {} bytes of vertices, {} vertices of {} floats need {}", source, bytes.size() - body, count, column, count * column * sizeof(float)));
  }
  msgs::GaussianSplatLayer layer;
  layer.sh_degree = degree;
  const int coefficients = coefficients_of(degree);
  const std::size_t sh_floats = 3 * static_cast<std::size_t>(coefficients);
  std::vector<std::size_t> rest_columns;  // channel-major
  for (int r = 0; r < rest; ++r) rest_columns.push_back(columns.at(fmt::format("f_rest_{}", r)));
  std::vector<float> row(column);
  const auto at = [&](const char* name) { return row[columns.at(name)]; };
  layer.sh.resize(count * sh_floats);
  for (std::size_t i = 0; i < count; ++i) {
    std::memcpy(row.data(), bytes.data() + body + i * column * sizeof(float), column * sizeof(float));
    for (const char* name : {"x", "y", "z"}) layer.positions.push_back(at(name));
    for (const char* name : {"scale_0", "scale_1", "scale_2"}) layer.log_scales.push_back(at(name));
    for (const char* name : {"rot_0", "rot_1", "rot_2", "rot_3"}) layer.rotations.push_back(at(name));
    layer.opacity_logits.push_back(at("opacity"));
    float* sh = &layer.sh[i * sh_floats];
    sh[0] = at("f_dc_0");
    sh[1] = at("f_dc_1");
    sh[2] = at("f_dc_2");
    for (int c = 0; c < 3; ++c) {
      for (int k = 1; k < coefficients; ++k) sh[3 * k + c] = row[rest_columns[static_cast<std::size_t>(c * (coefficients - 1) + (k - 1))]];
    }
  }
  if (Status valid = validate_splats(layer); !valid) return Error(fmt::format("{}: {}", source, valid.error().message));
  return layer;
}

}  // namespace hanzo::fusion::maps
