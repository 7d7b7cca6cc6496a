#include "hanzo/fusion/maps/map_diff.hpp"

#include <algorithm>
#include <cmath>
#include <unordered_set>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/maps/map_export.hpp"
#include "hanzo/fusion/maps/occupancy_grid.hpp"
#include "grid_image.hpp"

namespace hanzo::fusion::maps {
namespace {

/// A layer placed in world cell indices.
struct GridView {
  const msgs::OccupancyGridLayer* layer = nullptr;
  Eigen::Vector3i first = Eigen::Vector3i::Zero();
  Eigen::Vector3i size = Eigen::Vector3i::Zero();

  CellState state(const Eigen::Vector3i& cell, const MapDiffConfig& config) const {
    const Eigen::Vector3i local = cell - first;
    if ((local.array() < 0).any() || (local.array() >= size.array()).any()) return CellState::kUnknown;
    const std::size_t linear =
        (static_cast<std::size_t>(local.z()) * static_cast<std::size_t>(size.y()) + static_cast<std::size_t>(local.y())) *
            static_cast<std::size_t>(size.x()) +
        static_cast<std::size_t>(local.x());
    const float p = layer->occupancy[linear];
    if (p == 0.5f) return CellState::kUnknown;
    if (p > config.occupied_threshold) return CellState::kOccupied;
    if (p < config.free_threshold) return CellState::kFree;
    return CellState::kUnknown;
  }
};

Result<GridView> view_of(const msgs::OccupancyGridLayer& layer, const char* which) {
  GridView view;
  view.layer = &layer;
  HANZO_ASSIGN_OR_RETURN(view.first, with_context(occupancy_layer_first_cell(layer), which));
  view.size = Eigen::Vector3i(static_cast<int>(layer.size_x), static_cast<int>(layer.size_y), static_cast<int>(layer.size_z));
  return view;
}

Result<OccupancyDiff> diff_occupancy(const msgs::OccupancyGridLayer& before, const msgs::OccupancyGridLayer& after,
                                     const MapDiffConfig& config) {
  if (std::abs(before.resolution - after.resolution) > 1e-9 * after.resolution) {
    return Error{fmt::format("occupancy: resolutions differ ({} m and {} m); compare grids of the same resolution",
                             before.resolution, after.resolution),
                 "occupancy.resolution"};
  }
  if ((before.size_z > 1) != (after.size_z > 1)) {
    return Error{"occupancy: one grid is 2D and the other 3D", "occupancy.size_z"};
  }
  GridView old_view;
  GridView new_view;
  HANZO_ASSIGN_OR_RETURN(old_view, view_of(before, "before"));
  HANZO_ASSIGN_OR_RETURN(new_view, view_of(after, "after"));

  OccupancyDiff diff;
  diff.resolution = after.resolution;
  diff.three_dimensional = after.size_z > 1;
  const Eigen::Vector3i low = old_view.first.cwiseMin(new_view.first);
  const Eigen::Vector3i high = (old_view.first + old_view.size).cwiseMax(new_view.first + new_view.size);
  for (int z = low.z(); z < high.z(); ++z) {
    for (int y = low.y(); y < high.y(); ++y) {
      for (int x = low.x(); x < high.x(); ++x) {
        const Eigen::Vector3i cell(x, y, z);
        const CellState was = old_view.state(cell, config);
        const CellState is = new_view.state(cell, config);
        ++diff.cells_compared;
        if (was == is) continue;
        if (was == CellState::kUnknown) {
          ++diff.newly_observed;
        } else if (is == CellState::kUnknown) {
          ++diff.no_longer_observed;
        } else if (is == CellState::kOccupied) {
          ++diff.became_occupied;
          diff.appeared_cells.push_back(cell);
        } else {
          ++diff.became_free;
          diff.vanished_cells.push_back(cell);
        }
      }
    }
  }
  return diff;
}

std::unordered_set<uint64_t> voxel_keys(const msgs::PointLayer& layer, float inverse_voxel) {
  std::unordered_set<uint64_t> keys;
  keys.reserve(layer.points.size());
  for (const Eigen::Vector3f& point : layer.points) {
    uint64_t key = 0;
    if (cloud::pack_voxel_key(cloud::voxel_coordinates(point, inverse_voxel), &key)) keys.insert(key);
  }
  return keys;
}

/// Voxels of `from` with no voxel of `other` in their 3 x 3 x 3 neighbourhood, as centres.
std::vector<Eigen::Vector3f> unmatched(const std::unordered_set<uint64_t>& from, const std::unordered_set<uint64_t>& other,
                                       double voxel_size) {
  std::vector<Eigen::Vector3i> voxels;
  for (uint64_t key : from) {
    const Eigen::Vector3i voxel = cloud::unpack_voxel_key(key);
    bool matched = false;
    for (int dz = -1; dz <= 1 && !matched; ++dz) {
      for (int dy = -1; dy <= 1 && !matched; ++dy) {
        for (int dx = -1; dx <= 1 && !matched; ++dx) {
          uint64_t neighbour = 0;
          matched = cloud::pack_voxel_key(voxel + Eigen::Vector3i(dx, dy, dz), &neighbour) && other.contains(neighbour);
        }
      }
    }
    if (!matched) voxels.push_back(voxel);
  }
  std::sort(voxels.begin(), voxels.end(), [](const Eigen::Vector3i& a, const Eigen::Vector3i& b) {
    return std::tie(a.z(), a.y(), a.x()) < std::tie(b.z(), b.y(), b.x());
  });
  std::vector<Eigen::Vector3f> centres;
  centres.reserve(voxels.size());
  for (const Eigen::Vector3i& voxel : voxels) centres.push_back(((voxel.cast<double>().array() + 0.5) * voxel_size).cast<float>());
  return centres;
}

}  // namespace

Result<MapDiff> diff_maps(const msgs::FusionMap& before, const msgs::FusionMap& after, const MapDiffConfig& config) {
  MapDiff diff;
  if (before.occupancy && after.occupancy) {
    HANZO_ASSIGN_OR_RETURN(diff.occupancy, diff_occupancy(*before.occupancy, *after.occupancy, config));
  }
  if (before.points && after.points) {
    double voxel = config.point_voxel_size;
    if (!(voxel > 0.0)) voxel = std::max(before.points->voxel_size, after.points->voxel_size);
    if (!(voxel > 0.0)) voxel = 0.1;
    PointDiff points;
    points.voxel_size = voxel;
    const float inverse = static_cast<float>(1.0 / voxel);
    const auto old_keys = voxel_keys(*before.points, inverse);
    const auto new_keys = voxel_keys(*after.points, inverse);
    points.voxels_before = old_keys.size();
    points.voxels_after = new_keys.size();
    points.added = unmatched(new_keys, old_keys, voxel);
    points.removed = unmatched(old_keys, new_keys, voxel);
    diff.points = std::move(points);
  }
  if (!diff.occupancy && !diff.points) {
    return Error{"map diff: the maps share no occupancy or point layer to compare", "layers"};
  }
  return diff;
}

Status write_diff_png(const std::string& path, const msgs::OccupancyGridLayer& after, const OccupancyDiff& diff) {
  if (after.size_x == 0 || after.size_y == 0) return Error{"diff PNG: the occupancy grid is empty", "occupancy"};
  Eigen::Vector3i first;
  HANZO_ASSIGN_OR_RETURN(first, occupancy_layer_first_cell(after));
  const msgs::OccupancyGridLayer flat = flatten_occupancy(after);
  const cv::Mat grey = grid_image(flat, [](float p) -> uint8_t {
    if (p == 0.5f) return 160;
    return p > 0.65f ? 0 : (p < 0.196f ? 255 : 160);
  });
  cv::Mat colour;
  cv::cvtColor(grey, colour, cv::COLOR_GRAY2BGR);
  const auto paint = [&](const std::vector<Eigen::Vector3i>& cells, const cv::Vec3b& bgr) {
    for (const Eigen::Vector3i& cell : cells) {
      const Eigen::Vector3i local = cell - first;
      if (local.x() < 0 || local.y() < 0 || local.x() >= colour.cols || local.y() >= colour.rows) continue;
      colour.at<cv::Vec3b>(colour.rows - 1 - local.y(), local.x()) = bgr;
    }
  };
  paint(diff.appeared_cells, cv::Vec3b(0, 0, 255));
  paint(diff.vanished_cells, cv::Vec3b(0, 200, 0));
  return write_image(path, colour, ".png");
}

}  // namespace hanzo::fusion::maps
