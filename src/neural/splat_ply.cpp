#include "hanzo/fusion/neural/splat_ply.hpp"

#include <cstring>
#include <map>
#include <sstream>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"

namespace hanzo::fusion::neural {

namespace {

std::vector<std::string> property_names(int sh_degree) {
  std::vector<std::string> names = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"};
  for (int i = 0; i < 3 * (sh_coefficients(sh_degree) - 1); ++i) names.push_back(fmt::format("f_rest_{}", i));
  for (const char* name : {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"}) names.emplace_back(name);
  return names;
}

}  // namespace

Status write_splat_ply(const std::string& path, const GaussianCloud& cloud) {
  if (!cloud.consistent()) return Error(fmt::format("{}: the Gaussians' arrays are inconsistent or not finite", path));
  const std::vector<std::string> names = property_names(cloud.sh_degree);
  std::string out = fmt::format("ply\nformat binary_little_endian 1.0\nelement vertex {}\n", cloud.size());
  for (const std::string& name : names) out += "property float " + name + "\n";
  out += "end_header\n";
  const int coefficients = sh_coefficients(cloud.sh_degree);
  std::vector<float> row(names.size());
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    std::size_t j = 0;
    for (int a = 0; a < 3; ++a) row[j++] = cloud.position[3 * i + static_cast<std::size_t>(a)];
    for (int a = 0; a < 3; ++a) row[j++] = 0.0f;
    const float* sh = &cloud.sh[i * static_cast<std::size_t>(cloud.sh_floats())];
    for (int c = 0; c < 3; ++c) row[j++] = sh[c];
    for (int c = 0; c < 3; ++c) {
      for (int k = 1; k < coefficients; ++k) row[j++] = sh[3 * k + c];
    }
    row[j++] = cloud.opacity_logit[i];
    for (int a = 0; a < 3; ++a) row[j++] = cloud.log_scale[3 * i + static_cast<std::size_t>(a)];
    for (int a = 0; a < 4; ++a) row[j++] = cloud.rotation[4 * i + static_cast<std::size_t>(a)];
    out.append(reinterpret_cast<const char*>(row.data()), row.size() * sizeof(float));
  }
  return write_file_durably(path, out);
}

Result<GaussianCloud> read_splat_ply(const std::string& path) {
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, read_file(path));
  const std::size_t header_end = bytes.find("end_header\n");
  if (bytes.rfind("ply\n", 0) != 0 || header_end == std::string::npos) return Error(fmt::format("{}: not a PLY file", path));
  std::istringstream header(bytes.substr(0, header_end));
  std::string line;
  std::size_t count = 0;
  bool binary = false, vertex = false;
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
      vertex = name == "vertex";
      if (!vertex) return Error(fmt::format("{}: element '{}' (only vertices of Gaussians are read)", path, name));
    } else if (word == "property") {
      std::string type, name;
      words >> type >> name;
      if (type != "float") return Error(fmt::format("{}: property {} is {} (Gaussian PLYs hold floats)", path, name, type));
      columns[name] = column++;
    }
  }
  if (!binary) return Error(fmt::format("{}: not binary_little_endian", path));
  int rest = 0;
  while (columns.contains(fmt::format("f_rest_{}", rest))) ++rest;
  int degree = 0;
  while (degree <= kMaxShDegree && 3 * (sh_coefficients(degree) - 1) != rest) ++degree;
  if (degree > kMaxShDegree) return Error(fmt::format("{}: {} f_rest properties fit no spherical-harmonics degree up to 3", path, rest));
  for (const std::string& name : property_names(degree)) {
    if (name[0] != 'n' && !columns.contains(name)) return Error(fmt::format("{}: no property '{}'", path, name));
  }
  const std::size_t body = header_end + std::strlen("end_header\n");
  if (bytes.size() - body != count * column * sizeof(float)) {
    return Error(fmt::format("{}: {} bytes of vertices, {} vertices of {} floats need {}", path, bytes.size() - body, count, column, count * column * sizeof(float)));
  }
  GaussianCloud cloud;
  cloud.sh_degree = degree;
  const int coefficients = sh_coefficients(degree);
  std::vector<std::size_t> rest_columns;  // channel-major
  for (int r = 0; r < rest; ++r) rest_columns.push_back(columns.at(fmt::format("f_rest_{}", r)));
  std::vector<float> row(column);
  const auto at = [&](const std::string& name) { return row[columns.at(name)]; };
  for (std::size_t i = 0; i < count; ++i) {
    std::memcpy(row.data(), bytes.data() + body + i * column * sizeof(float), column * sizeof(float));
    cloud.add({at("x"), at("y"), at("z")}, {at("scale_0"), at("scale_1"), at("scale_2")}, {at("rot_0"), at("rot_1"), at("rot_2"), at("rot_3")}, at("opacity"),
              {at("f_dc_0"), at("f_dc_1"), at("f_dc_2")});
    float* sh = &cloud.sh[i * static_cast<std::size_t>(cloud.sh_floats())];
    for (int c = 0; c < 3; ++c) {
      for (int k = 1; k < coefficients; ++k) sh[3 * k + c] = row[rest_columns[static_cast<std::size_t>(c * (coefficients - 1) + (k - 1))]];
    }
  }
  if (!cloud.consistent()) return Error(fmt::format("{}: non-finite values", path));
  return cloud;
}

}  // namespace hanzo::fusion::neural
