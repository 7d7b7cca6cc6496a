#include "hanzo/fusion/cloud/scan_normals.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include <Eigen/Eigenvalues>

#include "hanzo/fusion/cloud/parallel.hpp"

namespace hanzo::fusion::cloud {

namespace {
constexpr uint32_t kEmpty = std::numeric_limits<uint32_t>::max();

// atan2(y, x) in float to about 1e-5 rad (a minimax polynomial of atan on [0, 1], folded into the
// octants): a range-image column is 1e-3 rad or wider, and libm's atan2 in double was an
// eighth of a 130k-point sweep's odometry time.
float fast_atan2(float y, float x) {
  const float ax = std::abs(x), ay = std::abs(y);
  const float largest = std::max(ax, ay);
  if (largest == 0.0F) return 0.0F;
  const float a = std::min(ax, ay) / largest;
  const float s = a * a;
  float angle = ((-0.0464964749F * s + 0.15931422F) * s - 0.327622764F) * s * a + a;
  if (ay > ax) angle = 1.57079637F - angle;
  if (x < 0.0F) angle = 3.14159274F - angle;
  return y < 0.0F ? -angle : angle;
}
}  // namespace

ScanNormalEstimator::ScanNormalEstimator(const PointCloud& scan, const ScanNormalConfig& config, int num_threads)
    : scan_(scan), config_(config) {
  if (!scan.has_rings() || scan.empty()) return;
  rings_ = static_cast<int>(*std::max_element(scan.rings.begin(), scan.rings.end())) + 1;
  columns_ = config.azimuth_bins;
  if (columns_ <= 0) {
    std::vector<int> per_ring(static_cast<std::size_t>(rings_), 0);
    for (const uint16_t ring : scan.rings) ++per_ring[ring];
    columns_ = std::max(16, *std::max_element(per_ring.begin(), per_ring.end()));
  }
  // Columns spanning about one ring spacing (the neighbourhood is then as wide as it is tall):
  // the median elevation step between adjacent rings over the azimuth bin width.
  window_ = config.column_window;
  if (window_ <= 0) {
    // 4096 points spread over the sweep suffice for each ring's median elevation (every 7th of a
    // 130k-point sweep was a third of this constructor's time): k times a large prime modulo the
    // size visits distinct indices whatever the order of rings and columns in the scan.
    const std::size_t samples = std::min<std::size_t>(scan.size(), 4096);
    std::vector<std::vector<float>> elevations(static_cast<std::size_t>(rings_));
    for (std::size_t k = 0; k < samples; ++k) {
      const std::size_t i = (k * 2654435761ULL) % scan.size();
      const Eigen::Vector3f& p = scan.positions[i];
      elevations[scan.rings[i]].push_back(fast_atan2(p.z(), std::sqrt(p.x() * p.x() + p.y() * p.y())));
    }
    std::vector<float> ring_elevation, steps;
    for (auto& values : elevations) {
      if (values.empty()) continue;
      std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2), values.end());
      ring_elevation.push_back(values[values.size() / 2]);
    }
    for (std::size_t r = 1; r < ring_elevation.size(); ++r) steps.push_back(std::abs(ring_elevation[r] - ring_elevation[r - 1]));
    float step = 0.0F;
    if (!steps.empty()) {
      std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2), steps.end());
      step = steps[steps.size() / 2];
    }
    window_ = std::clamp(static_cast<int>(std::lround(step / (2.0 * M_PI / columns_))), 1, std::max(1, columns_ / 8));
  }
  // Column-major (a column's rings side by side): a sweep arrives column by column, so the
  // points fill the image nearly in memory order (ring-major, each point of a column landed on
  // another page). The columns are computed in parallel chunks; then each cell keeps the first
  // point of the sweep that falls in it: one sequential pass from the last point to the first
  // (plain stores; an atomic minimum per point in the parallel pass cost twice as much as the
  // columns themselves).
  image_.assign(static_cast<std::size_t>(rings_) * static_cast<std::size_t>(columns_), kEmpty);
  column_of_.resize(scan.size());
  const float columns_per_turn = static_cast<float>(columns_ * 0.5 / M_PI);
  parallel_for(scan.size(), num_threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const Eigen::Vector3f& p = scan.positions[i];
      // The nearest column centre (azimuth >= 0: adding a half rounds): sensors fire at evenly
      // spaced azimuths, which then fall on the centres, far from the edges where fast_atan2's
      // error could move them across.
      int column = static_cast<int>((fast_atan2(p.y(), p.x()) + static_cast<float>(M_PI)) * columns_per_turn + 0.5F);
      if (column >= columns_) column -= columns_;  // azimuth pi wraps to column 0
      column_of_[i] = column;
    }
  });
  for (std::size_t i = scan.size(); i-- > 0;) image_[cell_index(scan.rings[i], column_of_[i])] = static_cast<uint32_t>(i);
}

Eigen::Vector3f ScanNormalEstimator::normal(std::size_t i) const {
  if (image_.empty()) return Eigen::Vector3f::Zero();
  const Eigen::Vector3f& p = scan_.positions[i];
  const float range = p.norm();
  const float max_distance = std::min(static_cast<float>(config_.max_neighbour_distance),
                                      static_cast<float>(config_.max_relative_distance) * range);
  const float max_squared = max_distance * max_distance;
  const int ring = scan_.rings[i];
  // At most about four columns on each side, evenly spread over the window.
  const int stride = std::max(1, window_ / 4);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();
  int count = 0, other_ring = 0;
  for (int r = std::max(0, ring - 1); r <= std::min(rings_ - 1, ring + 1); ++r) {
    for (int dc = -(window_ / stride) * stride; dc <= window_; dc += stride) {
      const uint32_t j = image_[cell_index(r, wrapped_column(column_of_[i] + dc))];
      if (j == kEmpty) continue;
      const Eigen::Vector3f d = scan_.positions[j] - p;  // relative to p: well conditioned in float
      if (d.squaredNorm() > max_squared) continue;
      const Eigen::Vector3d q = d.cast<double>();
      sum += q;
      outer.noalias() += q * q.transpose();
      ++count;
      other_ring += r != ring ? 1 : 0;
    }
  }
  if (other_ring < 2 || count < config_.min_neighbours) return Eigen::Vector3f::Zero();
  const Eigen::Vector3d mean = sum / count;
  const Eigen::Matrix3d covariance = outer / count - mean * mean.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
  solver.computeDirect(covariance);
  const Eigen::Vector3d eigenvalues = solver.eigenvalues().cwiseMax(0.0);
  if (!(eigenvalues(0) < config_.plane_ratio * eigenvalues(1))) return Eigen::Vector3f::Zero();
  Eigen::Vector3f normal = solver.eigenvectors().col(0).cast<float>().normalized();
  return normal.dot(p) > 0.0F ? Eigen::Vector3f(-normal) : normal;
}

bool ScanNormalEstimator::isolated(std::size_t i, float max_gap) const {
  if (image_.empty()) return false;
  const Eigen::Vector3f& p = scan_.positions[i];
  const int ring = scan_.rings[i];
  const float max_squared = max_gap * max_gap;
  for (int r = std::max(0, ring - 1); r <= std::min(rings_ - 1, ring + 1); ++r) {
    const int reach = r == ring ? 2 : 1;
    for (int dc = -reach; dc <= reach; ++dc) {
      const uint32_t j = image_[cell_index(r, wrapped_column(column_of_[i] + dc))];
      if (j == kEmpty || j == i) continue;
      if ((scan_.positions[j] - p).squaredNorm() <= max_squared) return false;
    }
  }
  return true;
}

std::vector<Eigen::Vector3f> estimate_scan_normals(const PointCloud& scan, const ScanNormalConfig& config) {
  std::vector<uint32_t> all(scan.size());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<uint32_t>(i);
  return estimate_scan_normals(scan, all, config);
}

std::vector<Eigen::Vector3f> estimate_scan_normals(const PointCloud& scan, const std::vector<uint32_t>& indices,
                                                   const ScanNormalConfig& config) {
  const ScanNormalEstimator estimator(scan, config);
  std::vector<Eigen::Vector3f> normals(indices.size());
  for (std::size_t n = 0; n < indices.size(); ++n) normals[n] = estimator.normal(indices[n]);
  return normals;
}

}  // namespace hanzo::fusion::cloud
