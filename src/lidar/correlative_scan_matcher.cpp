#include "hanzo/fusion/lidar/correlative_scan_matcher.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace hanzo::fusion::lidar {
namespace {

constexpr double kMaxGridCells = 64e6;
constexpr long kBlock = 4;  // translations per block side in the branch and bound

// Values on integer cells [x0, x0 + width) x [y0, y0 + height); 0 outside.
struct CellGrid {
  long x0 = 0, y0 = 0, width = 0, height = 0;
  std::vector<float> values;

  float at(long x, long y) const {
    x -= x0;
    y -= y0;
    if (x < 0 || y < 0 || x >= width || y >= height) return 0.0F;
    return values[static_cast<size_t>(y * width + x)];
  }
};

// L(cell) of the target points, cells of `resolution` with cell (0, 0) centred on `origin`.
// Each point is taken at its cell's centre, so one table of exp(-d^2 / (2 sigma^2)) over the
// cell offsets serves every point (the search is only as fine as a cell anyway).
CellGrid likelihood_grid(const PlanarPoints& points, const Eigen::Vector2d& origin, long width, long height, double resolution, double sigma) {
  CellGrid grid{0, 0, width, height, std::vector<float>(static_cast<size_t>(width * height), 0.0F)};
  const long reach = static_cast<long>(std::ceil(3.0 * sigma / resolution));
  const long side = 2 * reach + 1;
  std::vector<float> kernel(static_cast<size_t>(side * side));
  for (long y = -reach; y <= reach; ++y) {
    for (long x = -reach; x <= reach; ++x) {
      const double squared_distance = resolution * resolution * static_cast<double>(x * x + y * y);
      kernel[static_cast<size_t>((y + reach) * side + x + reach)] = static_cast<float>(std::exp(-squared_distance / (2.0 * sigma * sigma)));
    }
  }
  for (const Eigen::Vector2d& p : points) {
    const long cx = std::lround((p.x() - origin.x()) / resolution), cy = std::lround((p.y() - origin.y()) / resolution);
    for (long y = std::max(0L, cy - reach); y <= std::min(height - 1, cy + reach); ++y) {
      float* row = grid.values.data() + y * width;
      const float* kernel_row = kernel.data() + (y - cy + reach) * side + reach - cx;
      for (long x = std::max(0L, cx - reach); x <= std::min(width - 1, cx + reach); ++x) row[x] = std::max(row[x], kernel_row[x]);
    }
  }
  return grid;
}

// M(x, y) = max of `grid` over [x, x + block) x [y, y + block): a pose's score summed over M is
// an upper bound of the scores of the block x block translations it stands for.
CellGrid block_maximum(const CellGrid& grid, long block) {
  CellGrid rows{grid.x0 - block + 1, grid.y0, grid.width + block - 1, grid.height, {}};
  rows.values.resize(static_cast<size_t>(rows.width * rows.height));
  for (long y = 0; y < rows.height; ++y) {
    for (long x = 0; x < rows.width; ++x) {
      float maximum = 0.0F;
      for (long i = 0; i < block; ++i) maximum = std::max(maximum, grid.at(rows.x0 + x + i, rows.y0 + y));
      rows.values[static_cast<size_t>(y * rows.width + x)] = maximum;
    }
  }
  CellGrid blocks{rows.x0, grid.y0 - block + 1, rows.width, grid.height + block - 1, {}};
  blocks.values.resize(static_cast<size_t>(blocks.width * blocks.height));
  for (long y = 0; y < blocks.height; ++y) {
    for (long x = 0; x < blocks.width; ++x) {
      float maximum = 0.0F;
      for (long j = 0; j < block; ++j) maximum = std::max(maximum, rows.at(blocks.x0 + x, blocks.y0 + y + j));
      blocks.values[static_cast<size_t>(y * blocks.width + x)] = maximum;
    }
  }
  return blocks;
}

using Cells = std::vector<std::pair<long, long>>;

float sum_at(const CellGrid& grid, const Cells& cells, long dx, long dy) {
  float sum = 0.0F;
  for (const auto& [x, y] : cells) sum += grid.at(x + dx, y + dy);
  return sum;
}

// A block of block x block translations at one rotation, with its upper bound.
struct Candidate {
  float bound;
  size_t rotation;
  long dx, dy;
};

}  // namespace

Status CorrelativeScanMatcherConfig::validate() const {
  if (!(linear_window >= 0)) return Error(fmt::format("linear_window: {} < 0", linear_window));
  if (!(angular_window >= 0 && angular_window <= M_PI)) return Error(fmt::format("angular_window: {} outside [0, pi]", angular_window));
  if (!(resolution > 0)) return Error(fmt::format("resolution: {} <= 0", resolution));
  if (!(angular_step > 0)) return Error(fmt::format("angular_step: {} <= 0", angular_step));
  if (!(sigma > 0)) return Error(fmt::format("sigma: {} <= 0", sigma));
  return {};
}

Result<CorrelativeScanMatch> correlative_scan_match(const PlanarPoints& source, const PlanarPoints& target,
                                                    const SE2& T_target_source_guess, const CorrelativeScanMatcherConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  if (source.empty() || target.empty()) return Error("correlative scan match: the source or the target is empty");
  for (const PlanarPoints* points : {&source, &target}) {
    for (const Eigen::Vector2d& p : *points) {
      if (!p.allFinite()) return Error(fmt::format("correlative scan match: a {} point is not finite", points == &source ? "source" : "target"));
    }
  }
  Eigen::Vector2d lower = target.front(), upper = target.front();
  for (const Eigen::Vector2d& p : target) {
    lower = lower.cwiseMin(p);
    upper = upper.cwiseMax(p);
  }
  const Eigen::Vector2d origin = lower.array() - 3.0 * config.sigma;
  const Eigen::Vector2d extent = (upper - lower).array() + 6.0 * config.sigma;
  const double cells = std::ceil(extent.x() / config.resolution + 1) * std::ceil(extent.y() / config.resolution + 1);
  if (cells > kMaxGridCells) {
    return Error(fmt::format("correlative scan match: the target needs {:.0f} cells of {} m (limit {:.0f}); raise resolution", cells,
                             config.resolution, kMaxGridCells));
  }
  const CellGrid grid = likelihood_grid(target, origin, static_cast<long>(std::ceil(extent.x() / config.resolution)) + 1,
                                        static_cast<long>(std::ceil(extent.y() / config.resolution)) + 1, config.resolution, config.sigma);
  const long block = config.branch_and_bound ? kBlock : 1;
  const CellGrid bounds = block > 1 ? block_maximum(grid, block) : grid;

  // The source points' cells at each rotation, angles from the guess outwards.
  const long window = std::lround(config.linear_window / config.resolution);
  const long angle_steps = std::lround(config.angular_window / config.angular_step);
  const Eigen::Vector2d& t0 = T_target_source_guess.translation();
  std::vector<double> angles;
  std::vector<Cells> cells_at_angle;
  for (long k = 0; k <= 2 * angle_steps; ++k) {
    const long signed_step = (k % 2 == 1) ? (k + 1) / 2 : -(k / 2);
    angles.push_back(T_target_source_guess.angle() + static_cast<double>(signed_step) * config.angular_step);
    const Eigen::Matrix2d R = SE2(angles.back(), Eigen::Vector2d::Zero()).rotation_matrix();
    Cells cells_of_points;
    for (const Eigen::Vector2d& p : source) {
      const Eigen::Vector2d cell = (R * p + t0 - origin) / config.resolution;
      cells_of_points.emplace_back(std::lround(cell.x()), std::lround(cell.y()));
    }
    cells_at_angle.push_back(std::move(cells_of_points));
  }
  // Branch and bound (Olson 2009, sec. III-C, two levels): bound every block, then score the
  // translations of the blocks in descending bound order until no bound beats the best score.
  std::vector<Candidate> candidates;
  CorrelativeScanMatch best;
  for (size_t rotation = 0; rotation < angles.size(); ++rotation) {
    for (long dy = -window; dy <= window; dy += block) {
      for (long dx = -window; dx <= window; dx += block) {
        candidates.push_back({sum_at(bounds, cells_at_angle[rotation], dx, dy), rotation, dx, dy});
        ++best.poses_evaluated;
      }
    }
  }
  std::stable_sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) { return a.bound > b.bound; });
  best.T_target_source = T_target_source_guess;
  float best_sum = -1.0F;
  for (const Candidate& candidate : candidates) {
    if (candidate.bound <= best_sum) break;
    for (long dy = candidate.dy; dy < candidate.dy + block && dy <= window; ++dy) {
      for (long dx = candidate.dx; dx < candidate.dx + block && dx <= window; ++dx) {
        const float sum = block > 1 ? sum_at(grid, cells_at_angle[candidate.rotation], dx, dy) : candidate.bound;
        best.poses_evaluated += block > 1 ? 1 : 0;
        if (sum > best_sum) {
          best_sum = sum;
          best.T_target_source = SE2(angles[candidate.rotation], t0 + config.resolution * Eigen::Vector2d(static_cast<double>(dx), static_cast<double>(dy)));
        }
      }
    }
  }
  best.score = best_sum / static_cast<double>(source.size());
  return best;
}

}  // namespace hanzo::fusion::lidar
