// The 3D occupancy grid's voxels and the TSDF mesh's vertices labelled from the labelled points
// (geometric_labels.hpp: label_voxels, label_mesh).

#include <algorithm>
#include <array>
#include <cmath>
#include <unordered_map>

#include "hanzo/fusion/cloud/kdtree.hpp"
#include "hanzo/fusion/maps/geometric_labels.hpp"

namespace hanzo::fusion::maps {

void label_voxels(msgs::OccupancyGridLayer& grid, const msgs::PointLayer& points, double occupied_threshold) {
  grid.labels.clear();
  const std::size_t voxels = std::size_t{grid.size_x} * grid.size_y * grid.size_z;
  if (grid.size_z <= 1 || grid.occupancy.size() != voxels) return;
  std::unordered_map<std::size_t, std::array<uint32_t, 5>> votes;  // per voxel, points per label
  if (points.labels.size() == points.points.size()) {
    const SE3 T_grid_world = grid.origin.to_se3().inverse();
    for (std::size_t i = 0; i < points.points.size(); ++i) {
      const Eigen::Vector3d in_grid = T_grid_world * points.points[i].cast<double>() / grid.resolution;
      const double x = std::floor(in_grid.x()), y = std::floor(in_grid.y()), z = std::floor(in_grid.z());
      if (x < 0.0 || y < 0.0 || z < 0.0 || x >= grid.size_x || y >= grid.size_y || z >= grid.size_z) continue;
      const std::size_t voxel = (static_cast<std::size_t>(z) * grid.size_y + static_cast<std::size_t>(y)) * grid.size_x + static_cast<std::size_t>(x);
      ++votes.try_emplace(voxel, std::array<uint32_t, 5>{}).first->second[static_cast<std::size_t>(points.labels[i])];
    }
  }
  grid.labels.assign(voxels, msgs::SemanticLabel::kUnknown);
  for (std::size_t voxel = 0; voxel < voxels; ++voxel) {
    if (grid.occupancy[voxel] < occupied_threshold) continue;
    grid.labels[voxel] = msgs::SemanticLabel::kObstacle;
    const auto found = votes.find(voxel);
    if (found == votes.end()) continue;
    const std::array<uint32_t, 5>& counts = found->second;
    grid.labels[voxel] = static_cast<msgs::SemanticLabel>(std::max_element(counts.begin(), counts.end()) - counts.begin());
  }
}

void label_mesh(msgs::MeshLayer& mesh, const msgs::PointLayer& points, double max_distance) {
  mesh.vertex_labels.clear();
  if (mesh.vertices.empty() || points.labels.size() != points.points.size() || points.points.empty()) return;
  const cloud::KdTree tree(points.points);
  const auto max_squared = static_cast<float>(max_distance * max_distance);
  mesh.vertex_labels.assign(mesh.vertices.size(), msgs::SemanticLabel::kUnknown);
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
    uint32_t nearest = 0;
    float squared = 0.0F;
    if (tree.nearest(mesh.vertices[v], max_squared, &nearest, &squared)) mesh.vertex_labels[v] = points.labels[nearest];
  }
}

}  // namespace hanzo::fusion::maps
