#include "hanzo/fusion/maps/cell_classes.hpp"

#include <cmath>
#include <unordered_map>
#include <vector>

#include "class_votes.hpp"

namespace hanzo::fusion::maps {

void classify_cells(msgs::OccupancyGridLayer& grid, const msgs::PointLayer& points) {
  grid.classes.clear();
  if (points.classes.size() != points.points.size() || points.points.empty()) return;
  const std::size_t cells = std::size_t{grid.size_x} * grid.size_y * grid.size_z;
  const SE3 T_grid_world = grid.origin.to_se3().inverse();
  std::unordered_map<std::size_t, ClassVotes> votes;
  for (std::size_t i = 0; i < points.points.size(); ++i) {
    const uint16_t label = points.classes[i];
    if (label == msgs::kNoClass) continue;
    const Eigen::Vector3d in_grid = T_grid_world * points.points[i].cast<double>() / grid.resolution;
    const double x = std::floor(in_grid.x()), y = std::floor(in_grid.y()), z = grid.size_z > 1 ? std::floor(in_grid.z()) : 0.0;
    if (x < 0.0 || y < 0.0 || z < 0.0 || x >= grid.size_x || y >= grid.size_y || z >= grid.size_z) continue;
    const std::size_t cell = (static_cast<std::size_t>(z) * grid.size_y + static_cast<std::size_t>(y)) * grid.size_x + static_cast<std::size_t>(x);
    votes[cell].add(label);
  }
  grid.classes.assign(cells, msgs::kNoClass);
  for (const auto& [cell, cell_votes] : votes) grid.classes[cell] = cell_votes.most().first;
}

}  // namespace hanzo::fusion::maps
