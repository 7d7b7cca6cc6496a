#include "hanzo/fusion/neural/splat_ply.hpp"

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/maps/splat_ply.hpp"
#include "hanzo/fusion/neural/map_layers.hpp"

namespace hanzo::fusion::neural {

Status write_splat_ply(const std::string& path, const GaussianCloud& cloud) {
  if (!cloud.consistent()) return Error(fmt::format("{}: the Gaussians' arrays are inconsistent or not finite", path));
  return write_file_durably(path, maps::encode_splat_ply(to_splat_layer(cloud, {})));
}

Result<GaussianCloud> read_splat_ply(const std::string& path) {
  std::string bytes;
  HANZO_ASSIGN_OR_RETURN(bytes, read_file(path));
  msgs::GaussianSplatLayer layer;
  HANZO_ASSIGN_OR_RETURN(layer, maps::decode_splat_ply(bytes, path));
  return from_splat_layer(layer);
}

}  // namespace hanzo::fusion::neural
