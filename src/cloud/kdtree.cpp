#include "hanzo/fusion/cloud/kdtree.hpp"

#include <nanoflann.hpp>

namespace hanzo::fusion::cloud {
namespace {

// nanoflann's view of the point array.
struct PointArray {
  std::vector<Eigen::Vector3f> points;
  size_t kdtree_get_point_count() const { return points.size(); }
  float kdtree_get_pt(size_t index, size_t dim) const { return points[index][static_cast<Eigen::Index>(dim)]; }
  template <class BoundingBox>
  bool kdtree_get_bbox(BoundingBox&) const { return false; }
};

using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PointArray>, PointArray, 3, uint32_t>;

// Result set of one neighbour with an initial search radius, so that branches farther than
// the radius are pruned from the start (nanoflann's KNNResultSet starts unbounded).
class BoundedNearest {
 public:
  explicit BoundedNearest(float max_squared_distance) : distance_(max_squared_distance) {}
  bool full() const { return true; }
  float worstDist() const { return distance_; }
  bool addPoint(float distance, uint32_t index) {
    if (distance < distance_) {
      distance_ = distance;
      index_ = index;
      found_ = true;
    }
    return true;
  }
  bool found() const { return found_; }
  uint32_t index() const { return index_; }
  float distance() const { return distance_; }

 private:
  float distance_;
  uint32_t index_ = 0;
  bool found_ = false;
};

// Counts points within a radius and stops the search once `limit` are found.
class BoundedCount {
 public:
  BoundedCount(float squared_radius, size_t limit) : squared_radius_(squared_radius), limit_(limit) {}
  bool full() const { return true; }
  float worstDist() const { return squared_radius_; }
  bool addPoint(float distance, uint32_t) {
    if (distance < squared_radius_) ++count_;
    return count_ < limit_;
  }
  size_t count() const { return count_; }

 private:
  float squared_radius_;
  size_t limit_;
  size_t count_ = 0;
};

}  // namespace

struct KdTree::Impl {
  explicit Impl(std::vector<Eigen::Vector3f> points)
      : array{std::move(points)},
        // nanoflann 1.4 builds in its constructor unless told not to; built once, here.
        tree(3, array, nanoflann::KDTreeSingleIndexAdaptorParams(8, nanoflann::KDTreeSingleIndexAdaptorFlags::SkipInitialBuildIndex)) {
    if (!array.points.empty()) tree.buildIndex();
  }
  PointArray array;
  Tree tree;
};

KdTree::KdTree(std::vector<Eigen::Vector3f> points) : impl_(std::make_unique<Impl>(std::move(points))) {}
KdTree::~KdTree() = default;
KdTree::KdTree(KdTree&&) noexcept = default;
KdTree& KdTree::operator=(KdTree&&) noexcept = default;

size_t KdTree::size() const { return impl_->array.points.size(); }
const std::vector<Eigen::Vector3f>& KdTree::points() const { return impl_->array.points; }

bool KdTree::nearest(const Eigen::Vector3f& query, float max_squared_distance, uint32_t* index,
                     float* squared_distance) const {
  if (size() == 0) return false;
  BoundedNearest result(max_squared_distance);
  impl_->tree.findNeighbors(result, query.data(), nanoflann::SearchParams());
  if (!result.found()) return false;
  *index = result.index();
  *squared_distance = result.distance();
  return true;
}

size_t KdTree::knn(const Eigen::Vector3f& query, size_t k, uint32_t* indices, float* squared_distances) const {
  if (size() == 0 || k == 0) return 0;
  return impl_->tree.knnSearch(query.data(), k, indices, squared_distances);
}

size_t KdTree::count_within(const Eigen::Vector3f& query, float radius, size_t max_count) const {
  if (size() == 0 || max_count == 0) return 0;
  BoundedCount result(radius * radius, max_count);
  impl_->tree.findNeighbors(result, query.data(), nanoflann::SearchParams());
  return result.count();
}

void KdTree::radius_search(const Eigen::Vector3f& query, float radius, std::vector<uint32_t>* indices,
                           std::vector<float>* squared_distances) const {
  indices->clear();
  squared_distances->clear();
  if (size() == 0) return;
  std::vector<std::pair<uint32_t, float>> found;
  impl_->tree.radiusSearch(query.data(), radius * radius, found, nanoflann::SearchParams(32, 0.0f, true));
  indices->reserve(found.size());
  squared_distances->reserve(found.size());
  for (const auto& [index, distance] : found) {
    indices->push_back(index);
    squared_distances->push_back(distance);
  }
}

}  // namespace hanzo::fusion::cloud
