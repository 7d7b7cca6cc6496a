#include "hanzo/fusion/cloud/scan_normals.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include <Eigen/Eigenvalues>

namespace hanzo::fusion::cloud {

std::vector<Eigen::Vector3f> estimate_scan_normals(const PointCloud& scan, const ScanNormalConfig& config) {
  std::vector<uint32_t> all(scan.size());
  for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<uint32_t>(i);
  return estimate_scan_normals(scan, all, config);
}

std::vector<Eigen::Vector3f> estimate_scan_normals(const PointCloud& scan, const std::vector<uint32_t>& indices,
                                                   const ScanNormalConfig& config) {
  std::vector<Eigen::Vector3f> normals(indices.size(), Eigen::Vector3f::Zero());
  if (!scan.has_rings() || scan.empty()) return normals;
  const int rings = static_cast<int>(*std::max_element(scan.rings.begin(), scan.rings.end())) + 1;
  int columns = config.azimuth_bins;
  if (columns <= 0) {
    std::vector<int> per_ring(static_cast<std::size_t>(rings), 0);
    for (const uint16_t ring : scan.rings) ++per_ring[ring];
    columns = std::max(16, *std::max_element(per_ring.begin(), per_ring.end()));
  }
  // Columns spanning about one ring spacing (the neighbourhood is then as wide as it is tall):
  // the median elevation step between adjacent rings over the azimuth bin width.
  int window = config.column_window;
  if (window <= 0) {
    std::vector<std::vector<float>> elevations(static_cast<std::size_t>(rings));
    for (std::size_t i = 0; i < scan.size(); i += 7) {
      const Eigen::Vector3f& p = scan.positions[i];
      elevations[scan.rings[i]].push_back(std::atan2(p.z(), std::hypot(p.x(), p.y())));
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
    window = std::clamp(static_cast<int>(std::lround(step / (2.0 * M_PI / columns))), 1, columns / 8);
  }
  // At most about four columns on each side, evenly spread over the window.
  const int stride = std::max(1, window / 4);
  constexpr uint32_t kEmpty = std::numeric_limits<uint32_t>::max();
  std::vector<uint32_t> image(static_cast<std::size_t>(rings) * static_cast<std::size_t>(columns), kEmpty);
  std::vector<int> column_of(scan.size());
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const Eigen::Vector3f& p = scan.positions[i];
    const double azimuth = (std::atan2(static_cast<double>(p.y()), static_cast<double>(p.x())) + M_PI) / (2.0 * M_PI);
    const int column = std::min(columns - 1, static_cast<int>(azimuth * columns));
    column_of[i] = column;
    uint32_t& cell = image[static_cast<std::size_t>(scan.rings[i]) * static_cast<std::size_t>(columns) + static_cast<std::size_t>(column)];
    if (cell == kEmpty) cell = static_cast<uint32_t>(i);
  }

  std::vector<Eigen::Vector3d> neighbourhood;
  for (std::size_t n = 0; n < indices.size(); ++n) {
    const std::size_t i = indices[n];
    const Eigen::Vector3f& p = scan.positions[i];
    const float range = p.norm();
    const float max_distance = std::min(static_cast<float>(config.max_neighbour_distance),
                                        static_cast<float>(config.max_relative_distance) * range);
    const float max_squared = max_distance * max_distance;
    const int ring = scan.rings[i];
    neighbourhood.clear();
    int other_ring = 0;
    for (int r = std::max(0, ring - 1); r <= std::min(rings - 1, ring + 1); ++r) {
      for (int dc = -(window / stride) * stride; dc <= window; dc += stride) {
        const int column = (column_of[i] + dc + columns) % columns;
        const uint32_t j = image[static_cast<std::size_t>(r) * static_cast<std::size_t>(columns) + static_cast<std::size_t>(column)];
        if (j == kEmpty || (scan.positions[j] - p).squaredNorm() > max_squared) continue;
        neighbourhood.push_back(scan.positions[j].cast<double>());
        other_ring += r != ring ? 1 : 0;
      }
    }
    if (other_ring < 2 || static_cast<int>(neighbourhood.size()) < config.min_neighbours) continue;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const Eigen::Vector3d& q : neighbourhood) mean += q;
    mean /= static_cast<double>(neighbourhood.size());
    Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
    for (const Eigen::Vector3d& q : neighbourhood) covariance.noalias() += (q - mean) * (q - mean).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
    solver.computeDirect(covariance);
    const Eigen::Vector3d eigenvalues = solver.eigenvalues().cwiseMax(0.0);
    if (!(eigenvalues(0) < config.plane_ratio * eigenvalues(1))) continue;
    Eigen::Vector3f normal = solver.eigenvectors().col(0).cast<float>().normalized();
    if (normal.dot(p) > 0.0F) normal = -normal;
    normals[n] = normal;
  }
  return normals;
}

}  // namespace hanzo::fusion::cloud
