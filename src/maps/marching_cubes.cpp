// Marching cubes over the TSDF's voxel centres and over dense sample grids. The case tables (which cube edges the surface
// crosses, and how those crossings form triangles, for each of the 256 inside/outside corner
// patterns) are the classic ones of Lorensen & Cline as PCL ships them in
// pcl/surface/marching_cubes.h (pcl::edgeTable, pcl::triTable); PCL's corner numbering is used:
// corner i sits at (x, y, z) = ((i ^ i >> 1) & 1, i >> 2 & 1, i >> 1 & 1) from the cube's base.

#include <array>
#include <cmath>
#include <unordered_map>

#include <fmt/format.h>
#include <pcl/surface/marching_cubes.h>

#include "hanzo/fusion/maps/marching_cubes.hpp"
#include "tsdf_storage.hpp"

namespace hanzo::fusion::maps {
namespace {

constexpr std::array<std::array<int, 2>, 12> kEdgeCorners{{{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                                           {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}}};

Eigen::Vector3i corner_offset(int corner) {
  return {((corner ^ (corner >> 1)) & 1), (corner >> 2) & 1, (corner >> 1) & 1};
}

/// Triangulates the cube at `base` (voxel coordinates) whose corner values `lookup` gives (false:
/// unknown, no triangles), sharing vertices through `vertex_of_edge`; vertex positions are
/// `to_position(voxel coordinates)`.
template <typename Lookup, typename ToPosition>
void triangulate_cube(const Eigen::Vector3i& base, const Lookup& lookup, const ToPosition& to_position,
                      std::array<std::unordered_map<uint64_t, uint32_t>, 3>& vertex_of_edge, msgs::MeshLayer& mesh) {
  std::array<float, 8> values{};
  int cube_index = 0;
  for (int corner = 0; corner < 8; ++corner) {
    if (!lookup(base + corner_offset(corner), &values[static_cast<std::size_t>(corner)])) return;
    if (values[static_cast<std::size_t>(corner)] < 0.0f) cube_index |= 1 << corner;
  }
  if (pcl::edgeTable[cube_index] == 0) return;
  std::array<uint32_t, 12> edge_vertices{};
  for (int edge = 0; edge < 12; ++edge) {
    if ((pcl::edgeTable[cube_index] & (1u << edge)) == 0) continue;
    int a = kEdgeCorners[static_cast<std::size_t>(edge)][0];
    int b = kEdgeCorners[static_cast<std::size_t>(edge)][1];
    if ((corner_offset(b) - corner_offset(a)).sum() < 0) std::swap(a, b);
    const Eigen::Vector3i low = base + corner_offset(a);
    const Eigen::Vector3i step = corner_offset(b) - corner_offset(a);
    const int axis = step.x() != 0 ? 0 : (step.y() != 0 ? 1 : 2);
    const uint64_t low_key = TsdfStorage::block_key(low);  // same 21-bit packing, on voxels
    const auto [entry, inserted] = vertex_of_edge[static_cast<std::size_t>(axis)].emplace(low_key, static_cast<uint32_t>(mesh.vertices.size()));
    if (inserted) {
      const float da = values[static_cast<std::size_t>(a)];
      const float db = values[static_cast<std::size_t>(b)];
      const double t = da / (da - db);
      mesh.vertices.push_back(to_position((low.cast<double>().array() + t * step.cast<double>().array()).matrix()).template cast<float>());
    }
    edge_vertices[static_cast<std::size_t>(edge)] = entry->second;
  }
  for (int i = 0; pcl::triTable[cube_index][i] != -1; i += 3) {
    for (int k = 0; k < 3; ++k) mesh.triangle_indices.push_back(edge_vertices[static_cast<std::size_t>(pcl::triTable[cube_index][i + k])]);
  }
}

}  // namespace

Result<msgs::MeshLayer> marching_cubes(const SampleGrid& grid) {
  if (!(grid.spacing > 0.0)) return Error(fmt::format("marching cubes: spacing {} (expected > 0)", grid.spacing));
  if ((grid.size.array() < 0).any() || static_cast<std::size_t>(grid.size.cast<int64_t>().prod()) != grid.values.size()) {
    return Error(fmt::format("marching cubes: {} values for a {} x {} x {} grid", grid.values.size(), grid.size.x(), grid.size.y(), grid.size.z()));
  }
  msgs::MeshLayer mesh;
  std::array<std::unordered_map<uint64_t, uint32_t>, 3> vertex_of_edge;
  const auto lookup = [&grid](const Eigen::Vector3i& at, float* value) {
    *value = grid.values[static_cast<std::size_t>((int64_t{at.z()} * grid.size.y() + at.y()) * grid.size.x() + at.x())];
    return std::isfinite(*value);
  };
  const auto to_position = [&grid](const Eigen::Vector3d& voxel) -> Eigen::Vector3d { return grid.origin + grid.spacing * voxel; };
  for (int z = 0; z + 1 < grid.size.z(); ++z) {
    for (int y = 0; y + 1 < grid.size.y(); ++y) {
      for (int x = 0; x + 1 < grid.size.x(); ++x) triangulate_cube({x, y, z}, lookup, to_position, vertex_of_edge, mesh);
    }
  }
  return mesh;
}

msgs::MeshLayer marching_cubes(const TsdfStorage& storage) {
  msgs::MeshLayer mesh;
  const int size = storage.block_size;
  // Vertices shared between cubes: one per (voxel at the edge's low end, edge axis).
  std::array<std::unordered_map<uint64_t, uint32_t>, 3> vertex_of_edge;

  for (const uint64_t key : storage.sorted_keys()) {
    const Eigen::Vector3i block_index = TsdfStorage::block_from_key(key);
    // The block and its +x/+y/+z neighbours: a cube reaches at most one voxel past the block.
    std::array<const TsdfStorage::Block*, 8> neighbours{};
    for (int n = 0; n < 8; ++n) {
      const auto found = storage.blocks.find(TsdfStorage::block_key(block_index + Eigen::Vector3i(n & 1, (n >> 1) & 1, (n >> 2) & 1)));
      neighbours[static_cast<std::size_t>(n)] = found == storage.blocks.end() ? nullptr : found->second.get();
    }
    const auto lookup = [&](const Eigen::Vector3i& local, float* distance) {
      const int n = (local.x() >= size ? 1 : 0) | (local.y() >= size ? 2 : 0) | (local.z() >= size ? 4 : 0);
      const TsdfStorage::Block* block = neighbours[static_cast<std::size_t>(n)];
      if (block == nullptr) return false;
      const Eigen::Vector3i inside(local.x() % size, local.y() % size, local.z() % size);
      const std::size_t offset = static_cast<std::size_t>((inside.z() * size + inside.y()) * size + inside.x());
      if (block->weights[offset] == 0) return false;
      *distance = storage.distance_of(block->distances[offset]);
      return true;
    };

    const auto to_position = [&storage](const Eigen::Vector3d& voxel) -> Eigen::Vector3d { return (voxel.array() + 0.5).matrix() * storage.voxel_size; };
    for (int z = 0; z < size; ++z) {
      for (int y = 0; y < size; ++y) {
        for (int x = 0; x < size; ++x) {
          const Eigen::Vector3i local(x, y, z);
          triangulate_cube(block_index * size + local, [&](const Eigen::Vector3i& at, float* distance) { return lookup(at - block_index * size, distance); },
                           to_position, vertex_of_edge, mesh);
        }
      }
    }
  }
  return mesh;
}

}  // namespace hanzo::fusion::maps
