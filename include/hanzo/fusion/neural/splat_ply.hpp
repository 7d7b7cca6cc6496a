#pragma once
// Gaussians as the PLY file that 3D Gaussian splatting viewers read: the layout of
// maps/splat_ply.hpp (the reference implementation's), written and read as a GaussianCloud.
// read_splat_ply() refuses what decode_splat_ply() refuses, each error naming the file.

#include <string>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/neural/gaussian_cloud.hpp"

namespace hanzo::fusion::neural {

Status write_splat_ply(const std::string& path, const GaussianCloud& cloud);
Result<GaussianCloud> read_splat_ply(const std::string& path);

}  // namespace hanzo::fusion::neural
