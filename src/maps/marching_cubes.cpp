// Marching cubes over the TSDF's voxel centres. The case tables (which cube edges the surface
// crosses, and how those crossings form triangles, for each of the 256 inside/outside corner
// patterns) are the classic ones of Lorensen & Cline as PCL ships them in
// pcl/surface/marching_cubes.h (pcl::edgeTable, pcl::triTable); PCL's corner numbering is used:
// corner i sits at (x, y, z) = ((i ^ i >> 1) & 1, i >> 2 & 1, i >> 1 & 1) from the cube's base.

#include <array>
#include <unordered_map>

#include <pcl/surface/marching_cubes.h>

#include "tsdf_storage.hpp"

namespace hanzo::fusion::maps {
namespace {

constexpr std::array<std::array<int, 2>, 12> kEdgeCorners{{{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                                                           {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}}};

Eigen::Vector3i corner_offset(int corner) {
  return {((corner ^ (corner >> 1)) & 1), (corner >> 2) & 1, (corner >> 1) & 1};
}

}  // namespace

msgs::MeshLayer marching_cubes(const TsdfStorage& storage) {
  msgs::MeshLayer mesh;
  const int size = storage.block_size;
  // Vertices shared between cubes: one per (voxel at the edge's low end, edge axis).
  std::array<std::unordered_map<uint64_t, uint32_t>, 3> vertex_of_edge;
  std::array<Eigen::Vector3i, 8> offsets;
  for (int corner = 0; corner < 8; ++corner) offsets[static_cast<std::size_t>(corner)] = corner_offset(corner);

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

    for (int z = 0; z < size; ++z) {
      for (int y = 0; y < size; ++y) {
        for (int x = 0; x < size; ++x) {
          std::array<float, 8> values{};
          bool complete = true;
          int cube_index = 0;
          for (int corner = 0; corner < 8 && complete; ++corner) {
            complete = lookup(Eigen::Vector3i(x, y, z) + offsets[static_cast<std::size_t>(corner)], &values[static_cast<std::size_t>(corner)]);
            if (values[static_cast<std::size_t>(corner)] < 0.0f) cube_index |= 1 << corner;
          }
          if (!complete || pcl::edgeTable[cube_index] == 0) continue;
          const Eigen::Vector3i base = block_index * size + Eigen::Vector3i(x, y, z);
          std::array<uint32_t, 12> edge_vertices{};
          for (int edge = 0; edge < 12; ++edge) {
            if ((pcl::edgeTable[cube_index] & (1u << edge)) == 0) continue;
            int a = kEdgeCorners[static_cast<std::size_t>(edge)][0];
            int b = kEdgeCorners[static_cast<std::size_t>(edge)][1];
            if ((offsets[static_cast<std::size_t>(b)] - offsets[static_cast<std::size_t>(a)]).sum() < 0) std::swap(a, b);
            const Eigen::Vector3i low = base + offsets[static_cast<std::size_t>(a)];
            const Eigen::Vector3i step = offsets[static_cast<std::size_t>(b)] - offsets[static_cast<std::size_t>(a)];
            const int axis = step.x() != 0 ? 0 : (step.y() != 0 ? 1 : 2);
            const uint64_t low_key = TsdfStorage::block_key(low);  // same 21-bit packing, on voxels
            const auto [entry, inserted] = vertex_of_edge[static_cast<std::size_t>(axis)].emplace(low_key, static_cast<uint32_t>(mesh.vertices.size()));
            if (inserted) {
              const float da = values[static_cast<std::size_t>(a)];
              const float db = values[static_cast<std::size_t>(b)];
              const double t = da / (da - db);
              const Eigen::Vector3d position = (low.cast<double>().array() + 0.5 + t * step.cast<double>().array()) * storage.voxel_size;
              mesh.vertices.push_back(position.cast<float>());
            }
            edge_vertices[static_cast<std::size_t>(edge)] = entry->second;
          }
          for (int i = 0; pcl::triTable[cube_index][i] != -1; i += 3) {
            for (int k = 0; k < 3; ++k) {
              mesh.triangle_indices.push_back(edge_vertices[static_cast<std::size_t>(pcl::triTable[cube_index][i + k])]);
            }
          }
        }
      }
    }
  }
  return mesh;
}

}  // namespace hanzo::fusion::maps
