#pragma once
// Marching cubes (Lorensen & Cline 1987) over a dense grid of samples: the surface where the
// samples cross zero, negative inside (a signed distance; a density as threshold - density).
// The TSDF extracts its meshes the same way over its sparse blocks (TsdfVolume::extract_mesh).

#include <span>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"

namespace hanzo::fusion::maps {

/// A grid of samples: value (x, y, z) at origin + spacing (x, y, z), stored x fastest, then y, then
/// z; non-finite values are unknown (no triangle touches them).
struct SampleGrid {
  Eigen::Vector3i size = Eigen::Vector3i::Zero();
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  double spacing = 1.0;
  std::span<const float> values;
};

/// The zero-crossing mesh, vertices shared between neighbouring cubes, in the grid's frame and
/// units. Fails when values.size() is not size.prod() or spacing is not positive.
Result<msgs::MeshLayer> marching_cubes(const SampleGrid& grid);

}  // namespace hanzo::fusion::maps
