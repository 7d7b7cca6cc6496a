#include "hanzo/fusion/lidar/correlative_scan_matcher.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace hanzo::fusion::lidar {
namespace {

constexpr double kMaxGridCells = 64e6;

// L(cell) of the target points on a grid with a margin of 3 sigma around them.
class LikelihoodGrid {
 public:
  LikelihoodGrid(const PlanarPoints& points, double resolution, double sigma) : resolution_(resolution) {
    Eigen::Vector2d lower = points.front(), upper = points.front();
    for (const Eigen::Vector2d& p : points) {
      lower = lower.cwiseMin(p);
      upper = upper.cwiseMax(p);
    }
    const double margin = 3.0 * sigma;
    origin_ = lower.array() - margin;
    width_ = static_cast<long>(std::ceil((upper.x() - lower.x() + 2 * margin) / resolution)) + 1;
    height_ = static_cast<long>(std::ceil((upper.y() - lower.y() + 2 * margin) / resolution)) + 1;
  }
  double cells() const { return static_cast<double>(width_) * static_cast<double>(height_); }

  void rasterize(const PlanarPoints& points, double sigma) {
    values_.assign(static_cast<size_t>(width_ * height_), 0.0F);
    const long reach = static_cast<long>(std::ceil(3.0 * sigma / resolution_));
    const double inverse_two_sigma_squared = 1.0 / (2.0 * sigma * sigma);
    for (const Eigen::Vector2d& p : points) {
      const long cx = cell_x(p.x()), cy = cell_y(p.y());
      for (long y = std::max(0L, cy - reach); y <= std::min(height_ - 1, cy + reach); ++y) {
        for (long x = std::max(0L, cx - reach); x <= std::min(width_ - 1, cx + reach); ++x) {
          const Eigen::Vector2d centre = origin_ + resolution_ * Eigen::Vector2d(static_cast<double>(x), static_cast<double>(y));
          const auto likelihood = static_cast<float>(std::exp(-(centre - p).squaredNorm() * inverse_two_sigma_squared));
          float& value = values_[static_cast<size_t>(y * width_ + x)];
          value = std::max(value, likelihood);
        }
      }
    }
  }

  long cell_x(double x) const { return std::lround((x - origin_.x()) / resolution_); }
  long cell_y(double y) const { return std::lround((y - origin_.y()) / resolution_); }
  long width() const { return width_; }
  long height() const { return height_; }
  const float* row(long y) const { return values_.data() + y * width_; }

 private:
  double resolution_;
  Eigen::Vector2d origin_;
  long width_ = 0, height_ = 0;
  std::vector<float> values_;
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
  LikelihoodGrid grid(target, config.resolution, config.sigma);
  if (grid.cells() > kMaxGridCells) {
    return Error(fmt::format("correlative scan match: the target needs {:.0f} cells of {} m (limit {:.0f}); raise resolution",
                             grid.cells(), config.resolution, kMaxGridCells));
  }
  grid.rasterize(target, config.sigma);

  const long window = std::lround(config.linear_window / config.resolution);
  const long side = 2 * window + 1;
  const long angle_steps = std::lround(config.angular_window / config.angular_step);
  std::vector<float> scores(static_cast<size_t>(side * side));
  // Ties keep the pose closest to the guess: translations nearest first, angles from the guess outwards.
  std::vector<std::pair<long, long>> offsets_nearest_first;
  for (long dy = -window; dy <= window; ++dy) {
    for (long dx = -window; dx <= window; ++dx) offsets_nearest_first.emplace_back(dx, dy);
  }
  std::stable_sort(offsets_nearest_first.begin(), offsets_nearest_first.end(),
                   [](const auto& a, const auto& b) { return a.first * a.first + a.second * a.second < b.first * b.first + b.second * b.second; });
  CorrelativeScanMatch best;
  best.T_target_source = T_target_source_guess;
  double best_sum = -1.0;
  const Eigen::Vector2d& t0 = T_target_source_guess.translation();
  for (long k = 0; k <= 2 * angle_steps; ++k) {
    const long signed_step = (k % 2 == 1) ? (k + 1) / 2 : -(k / 2);
    const double angle = T_target_source_guess.angle() + static_cast<double>(signed_step) * config.angular_step;
    const Eigen::Matrix2d R = SE2(angle, Eigen::Vector2d::Zero()).rotation_matrix();
    std::fill(scores.begin(), scores.end(), 0.0F);
    for (const Eigen::Vector2d& p : source) {
      const Eigen::Vector2d q = R * p + t0;
      const long cx = grid.cell_x(q.x()), cy = grid.cell_y(q.y());
      const long x_begin = std::max(-window, -cx), x_end = std::min(window, grid.width() - 1 - cx);
      if (x_begin > x_end) continue;
      for (long dy = std::max(-window, -cy); dy <= std::min(window, grid.height() - 1 - cy); ++dy) {
        const float* row = grid.row(cy + dy);
        float* out = scores.data() + (dy + window) * side + window;
        for (long dx = x_begin; dx <= x_end; ++dx) out[dx] += row[cx + dx];
      }
    }
    best.poses_evaluated += scores.size();
    for (const auto& [dx, dy] : offsets_nearest_first) {
      const double sum = scores[static_cast<size_t>((dy + window) * side + dx + window)];
      if (sum > best_sum) {
        best_sum = sum;
        best.T_target_source = SE2(angle, t0 + config.resolution * Eigen::Vector2d(static_cast<double>(dx), static_cast<double>(dy)));
      }
    }
  }
  best.score = best_sum / static_cast<double>(source.size());
  return best;
}

}  // namespace hanzo::fusion::lidar
