#include "hanzo/fusion/cloud/outlier_removal.hpp"

#include "hanzo/fusion/cloud/kdtree.hpp"
#include "hanzo/fusion/cloud/parallel.hpp"

namespace hanzo::fusion::cloud {

std::vector<uint32_t> inlier_indices(const PointCloud& cloud, const OutlierRemovalConfig& config) {
  const KdTree tree(cloud.positions);
  std::vector<uint8_t> keep(cloud.size(), 0);
  // +1: the query point is in the tree and counts itself.
  const size_t required = static_cast<size_t>(std::max(config.min_neighbors, 0)) + 1;
  const float radius = static_cast<float>(config.radius);
  parallel_for(cloud.size(), config.num_threads, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) keep[i] = tree.count_within(cloud.positions[i], radius, required) >= required;
  });
  std::vector<uint32_t> kept;
  kept.reserve(cloud.size());
  for (size_t i = 0; i < keep.size(); ++i) {
    if (keep[i]) kept.push_back(static_cast<uint32_t>(i));
  }
  return kept;
}

PointCloud remove_outliers(const PointCloud& cloud, const OutlierRemovalConfig& config) {
  return select(cloud, inlier_indices(cloud, config));
}

}  // namespace hanzo::fusion::cloud
