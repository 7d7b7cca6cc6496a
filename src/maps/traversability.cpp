#include "hanzo/fusion/maps/traversability.hpp"

#include <algorithm>
#include <optional>
#include <utility>

#include <Eigen/Dense>
#include <fmt/format.h>

namespace hanzo::fusion::maps {
namespace {

// The cell of a point (x fastest), none outside the grid.
std::optional<std::size_t> cell_of(const Eigen::Vector3d& in_grid, const msgs::OccupancyGridLayer& grid) {
  const auto x = static_cast<long>(std::floor(in_grid.x() / grid.resolution));
  const auto y = static_cast<long>(std::floor(in_grid.y() / grid.resolution));
  if (x < 0 || y < 0 || x >= static_cast<long>(grid.size_x) || y >= static_cast<long>(grid.size_y)) return std::nullopt;
  return static_cast<std::size_t>(y) * grid.size_x + static_cast<std::size_t>(x);
}

// The ground height from one cell's candidate heights (sorted): the median of those within
// max_step of the 10th percentile.
float ground_height(const std::vector<float>& sorted_heights, double max_step) {
  const float low = sorted_heights[sorted_heights.size() / 10];
  const auto first = std::lower_bound(sorted_heights.begin(), sorted_heights.end(), static_cast<float>(low - max_step));
  const auto last = std::upper_bound(sorted_heights.begin(), sorted_heights.end(), static_cast<float>(low + max_step));
  return *(first + (last - first) / 2);
}

}  // namespace

Status TraversabilityConfig::validate() const {
  if (!(max_slope_deg > 0.0 && max_slope_deg < 90.0)) return Error(fmt::format("max_slope_deg: {} (0 to 90)", max_slope_deg));
  if (!(max_step_m > 0.0)) return Error(fmt::format("max_step_m: {} (> 0)", max_step_m));
  if (!(robot_height_m > max_step_m)) return Error(fmt::format("robot_height_m: {} (above max_step_m)", robot_height_m));
  if (!(ground_max_tilt_deg > 0.0 && ground_max_tilt_deg < 90.0)) return Error(fmt::format("ground_max_tilt_deg: {} (0 to 90)", ground_max_tilt_deg));
  return ok_status();
}

std::vector<GroundCell> ground_cells(const msgs::OccupancyGridLayer& grid, const std::vector<Eigen::Vector3f>& points,
                                     const std::vector<Eigen::Vector3f>& normals, const TraversabilityConfig& config) {
  if (grid.size_z != 1 || grid.size_x == 0 || grid.size_y == 0 || normals.size() != points.size()) return {};
  std::vector<GroundCell> cells(static_cast<std::size_t>(grid.size_x) * grid.size_y);
  const SE3 T_grid_world = grid.origin.to_se3().inverse();
  const double min_normal_z = std::cos(config.ground_max_tilt_deg * M_PI / 180.0);

  // Each point's cell; the ground candidates' heights by cell.
  std::vector<std::pair<std::size_t, float>> column_of(points.size(), {cells.size(), 0.0F});  // (cell or none, z)
  std::vector<std::pair<std::size_t, float>> candidates;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const std::optional<std::size_t> cell = cell_of(T_grid_world * points[i].cast<double>(), grid);
    if (!cell) continue;
    column_of[i] = {*cell, points[i].z()};
    if (std::abs(normals[i].z()) >= min_normal_z) candidates.emplace_back(*cell, points[i].z());
  }
  std::sort(candidates.begin(), candidates.end());
  std::vector<float> heights;
  for (std::size_t begin = 0; begin < candidates.size();) {
    std::size_t end = begin;
    heights.clear();
    for (; end < candidates.size() && candidates[end].first == candidates[begin].first; ++end) heights.push_back(candidates[end].second);
    GroundCell& cell = cells[candidates[begin].first];
    cell.height = ground_height(heights, config.max_step_m);
    cell.step_m = heights[heights.size() * 9 / 10] - heights[heights.size() / 10];  // two levels in one cell: a step within it
    begin = end;
  }

  for (const auto& [cell, z] : column_of) {
    if (cell >= cells.size() || !cells[cell].has_ground()) continue;
    const float above = z - cells[cell].height;
    if (above > config.max_step_m && above <= config.robot_height_m) cells[cell].blocked = true;
  }

  // Slope and step from the 3 x 3 neighbourhood (cell centres in the grid frame, in cells).
  for (uint32_t y = 0; y < grid.size_y; ++y) {
    for (uint32_t x = 0; x < grid.size_x; ++x) {
      GroundCell& cell = cells[static_cast<std::size_t>(y) * grid.size_x + x];
      if (!cell.has_ground()) continue;
      Eigen::Matrix3d normal_equations = Eigen::Matrix3d::Zero();
      Eigen::Vector3d right_side = Eigen::Vector3d::Zero();
      int used = 0;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const long nx = static_cast<long>(x) + dx, ny = static_cast<long>(y) + dy;
          if (nx < 0 || ny < 0 || nx >= static_cast<long>(grid.size_x) || ny >= static_cast<long>(grid.size_y)) continue;
          const GroundCell& neighbour = cells[static_cast<std::size_t>(ny) * grid.size_x + static_cast<std::size_t>(nx)];
          if (!neighbour.has_ground()) continue;
          cell.step_m = std::max(cell.step_m, std::abs(neighbour.height - cell.height));
          const Eigen::Vector3d row(dx * grid.resolution, dy * grid.resolution, 1.0);
          normal_equations += row * row.transpose();
          right_side += row * static_cast<double>(neighbour.height - cell.height);
          ++used;
        }
      }
      if (used < 3) continue;
      const Eigen::FullPivLU<Eigen::Matrix3d> solver(normal_equations);
      if (solver.rank() < 3) continue;  // the cells lie on a line
      const Eigen::Vector3d plane = solver.solve(right_side);
      cell.slope_deg = static_cast<float>(std::atan(plane.head<2>().norm()) * 180.0 / M_PI);
    }
  }
  return cells;
}

}  // namespace hanzo::fusion::maps
