#pragma once
// Outlier removal as the spec defines it ("Statistical outlier removal"): a point with fewer
// than `min_neighbors` other points within `radius` is isolated sensor noise (rain, dust,
// multipath) and is dropped. Spec defaults K = 10, R = 0.5 m.

#include <cstdint>
#include <vector>

#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::cloud {

struct OutlierRemovalConfig {
  int min_neighbors = 10;  // other points required within radius
  double radius = 0.5;     // m
  int num_threads = 1;
};

/// Indices of the points of `cloud` that are kept, ascending.
std::vector<uint32_t> inlier_indices(const PointCloud& cloud, const OutlierRemovalConfig& config = {});
/// `cloud` without its outliers (every attribute).
PointCloud remove_outliers(const PointCloud& cloud, const OutlierRemovalConfig& config = {});

}  // namespace hanzo::fusion::cloud
