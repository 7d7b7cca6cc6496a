#include "hanzo/fusion/cloud/octree.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"

namespace hanzo::fusion::cloud {
namespace {

// Points this far (m) from the first point are refused: growing the root toward them would take
// more doublings than float precision allows.
constexpr float kMaxReach = 1.0e6F;

int octant_of(const Eigen::Vector3f& point, const Eigen::Vector3f& center) {
  return (point.x() >= center.x() ? 1 : 0) | (point.y() >= center.y() ? 2 : 0) | (point.z() >= center.z() ? 4 : 0);
}

// Squared distance from `query` to the cube (center, half_size); 0 inside.
float box_squared_distance(const Eigen::Vector3f& query, const Eigen::Vector3f& center, float half_size) {
  const Eigen::Vector3f gap = ((query - center).cwiseAbs().array() - half_size).cwiseMax(0.0F);
  return gap.squaredNorm();
}

// Squared distance from `query` to the farthest corner of the cube.
float box_farthest_squared_distance(const Eigen::Vector3f& query, const Eigen::Vector3f& center, float half_size) {
  return ((query - center).cwiseAbs().array() + half_size).matrix().squaredNorm();
}

}  // namespace

Status OctreeConfig::validate() const {
  if (bucket_size < 1) return Error("bucket_size: 0 (need at least 1)");
  if (!(min_leaf_size > 0)) return Error(fmt::format("min_leaf_size: {} <= 0", min_leaf_size));
  if (!(min_point_spacing >= 0)) return Error(fmt::format("min_point_spacing: {} < 0", min_point_spacing));
  if (!(initial_size > 0) || !std::isfinite(initial_size)) return Error(fmt::format("initial_size: {} is not positive", initial_size));
  return ok_status();
}

Octree::Octree(OctreeConfig config) : config_(config) {
  if (Status valid = config_.validate(); !valid) {
    logger()->warn("octree: {}; using the defaults", valid.error().message);
    config_ = OctreeConfig{};
  }
}

void Octree::clear() {
  nodes_.clear();
  free_nodes_.clear();
  point_count_ = 0;
}

uint32_t Octree::allocate_children(const Node& parent) {
  const Eigen::Vector3f center = parent.center;
  const float quarter = parent.half_size * 0.5F;
  uint32_t block = 0;
  if (!free_nodes_.empty()) {
    block = free_nodes_.back();
    free_nodes_.pop_back();
  } else {
    block = static_cast<uint32_t>(nodes_.size());
    nodes_.resize(nodes_.size() + 8);
  }
  for (int octant = 0; octant < 8; ++octant) {
    Node& child = nodes_[block + static_cast<uint32_t>(octant)];
    child.center = center + quarter * Eigen::Vector3f((octant & 1) ? 1.0F : -1.0F, (octant & 2) ? 1.0F : -1.0F, (octant & 4) ? 1.0F : -1.0F);
    child.half_size = quarter;
    child.first_child = kNone;
    child.points.clear();
  }
  return block;
}

void Octree::grow_to(const Eigen::Vector3f& point) {
  if (nodes_.empty()) {
    nodes_.emplace_back();
    nodes_[0].center = point;
    nodes_[0].half_size = static_cast<float>(config_.initial_size * 0.5);
    return;
  }
  while ((point - nodes_[0].center).cwiseAbs().maxCoeff() >= nodes_[0].half_size) {
    // The new root, twice the size, extends toward the point; the old root is its octant on the
    // other side.
    const Eigen::Vector3f old_center = nodes_[0].center;
    const float half = nodes_[0].half_size;
    const Eigen::Vector3f toward((point.x() >= old_center.x()) ? 1.0F : -1.0F, (point.y() >= old_center.y()) ? 1.0F : -1.0F,
                                 (point.z() >= old_center.z()) ? 1.0F : -1.0F);
    Node root;
    root.center = old_center + half * toward;
    root.half_size = 2.0F * half;
    const uint32_t block = allocate_children(root);
    const auto old_octant = static_cast<uint32_t>(octant_of(old_center, root.center));
    nodes_[block + old_octant] = std::move(nodes_[0]);
    root.first_child = block;
    nodes_[0] = std::move(root);
  }
}

bool Octree::insert_point(const Eigen::Vector3f& point) {
  grow_to(point);
  uint32_t node = 0;
  while (nodes_[node].first_child != kNone) node = nodes_[node].first_child + static_cast<uint32_t>(octant_of(point, nodes_[node].center));
  std::vector<Eigen::Vector3f>& bucket = nodes_[node].points;
  if (config_.min_point_spacing > 0) {
    const auto spacing_squared = static_cast<float>(config_.min_point_spacing * config_.min_point_spacing);
    for (const Eigen::Vector3f& existing : bucket) {
      if ((existing - point).squaredNorm() < spacing_squared) return false;
    }
  }
  bucket.push_back(point);
  ++point_count_;
  if (bucket.size() > config_.bucket_size && 2.0 * nodes_[node].half_size > config_.min_leaf_size) split(node);
  return true;
}

void Octree::split(uint32_t node) {
  const uint32_t block = allocate_children(nodes_[node]);
  std::vector<Eigen::Vector3f> points = std::move(nodes_[node].points);
  nodes_[node].points = {};
  nodes_[node].first_child = block;
  const Eigen::Vector3f center = nodes_[node].center;
  for (const Eigen::Vector3f& point : points) nodes_[block + static_cast<uint32_t>(octant_of(point, center))].points.push_back(point);
  // All points in one octant: that child splits again (its edge still above min_leaf_size).
  for (uint32_t child = block; child < block + 8; ++child) {
    if (nodes_[child].points.size() > config_.bucket_size && 2.0 * nodes_[child].half_size > config_.min_leaf_size) split(child);
  }
}

std::size_t Octree::insert(const std::vector<Eigen::Vector3f>& points) {
  std::size_t inserted = 0;
  for (const Eigen::Vector3f& point : points) {
    const bool reachable = nodes_.empty() || (point - nodes_[0].center).cwiseAbs().maxCoeff() < kMaxReach;
    if (!point.allFinite() || !reachable) {
      ++skipped_points_;
      continue;
    }
    inserted += insert_point(point) ? 1 : 0;
  }
  return inserted;
}

void Octree::free_subtree(uint32_t node) {
  const uint32_t block = nodes_[node].first_child;
  if (block == kNone) return;
  for (uint32_t child = block; child < block + 8; ++child) {
    free_subtree(child);
    nodes_[child].points = {};
  }
  free_nodes_.push_back(block);
  nodes_[node].first_child = kNone;
}

std::size_t Octree::remove_outside(uint32_t node, const Eigen::Vector3f& center, float squared_radius) {
  const Node& n = nodes_[node];
  if (box_farthest_squared_distance(center, n.center, n.half_size) <= squared_radius) return 0;  // all inside
  std::size_t removed = 0;
  if (n.first_child == kNone) {
    std::vector<Eigen::Vector3f>& bucket = nodes_[node].points;
    const std::size_t before = bucket.size();
    std::erase_if(bucket, [&](const Eigen::Vector3f& p) { return (p - center).squaredNorm() > squared_radius; });
    if (bucket.empty()) bucket.shrink_to_fit();
    return before - bucket.size();
  }
  const uint32_t block = n.first_child;
  bool all_empty = true;
  for (uint32_t child = block; child < block + 8; ++child) {
    removed += remove_outside(child, center, squared_radius);
    all_empty = all_empty && nodes_[child].first_child == kNone && nodes_[child].points.empty();
  }
  if (all_empty) free_subtree(node);  // the node becomes an empty leaf
  return removed;
}

std::size_t Octree::remove_outside(const Eigen::Vector3f& center, float radius) {
  if (nodes_.empty()) return 0;
  const std::size_t removed = remove_outside(0, center, radius * radius);
  point_count_ -= removed;
  return removed;
}

template <typename Visit>
void Octree::search(uint32_t node, const Eigen::Vector3f& query, float& bound, Visit& visit) const {
  const Node& n = nodes_[node];
  if (n.first_child == kNone) {
    for (const Eigen::Vector3f& point : n.points) {
      const float d = (point - query).squaredNorm();
      if (d < bound) visit(point, d, bound);
    }
    return;
  }
  // Octants nearest first: the bound shrinks early and prunes the rest.
  std::array<std::pair<float, uint32_t>, 8> order;
  for (uint32_t octant = 0; octant < 8; ++octant) {
    const Node& child = nodes_[n.first_child + octant];
    order[octant] = {box_squared_distance(query, child.center, child.half_size), n.first_child + octant};
  }
  std::sort(order.begin(), order.end());
  for (const auto& [distance, child] : order) {
    if (distance >= bound) break;
    search(child, query, bound, visit);
  }
}

void Octree::knn(const Eigen::Vector3f& query, std::size_t k, std::vector<Eigen::Vector3f>* points,
                 std::vector<float>* squared_distances, float max_squared_distance) const {
  points->clear();
  if (squared_distances) squared_distances->clear();
  if (k == 0 || nodes_.empty() || !query.allFinite()) return;
  thread_local std::vector<std::pair<float, Eigen::Vector3f>> best;  // reused: no allocation per query
  best.clear();
  auto visit = [&](const Eigen::Vector3f& point, float d, float& bound) {
    const auto position = std::upper_bound(best.begin(), best.end(), d, [](float value, const auto& entry) { return value < entry.first; });
    best.insert(position, {d, point});
    if (best.size() > k) best.pop_back();
    if (best.size() == k) bound = best.back().first;
  };
  float bound = max_squared_distance;
  search(0, query, bound, visit);
  for (const auto& [d, point] : best) {
    points->push_back(point);
    if (squared_distances) squared_distances->push_back(d);
  }
}

bool Octree::nearest(const Eigen::Vector3f& query, float max_squared_distance, Eigen::Vector3f* point, float* squared_distance) const {
  thread_local std::vector<Eigen::Vector3f> found;
  thread_local std::vector<float> distances;
  knn(query, 1, &found, &distances, max_squared_distance);
  if (found.empty()) return false;
  *point = found.front();
  *squared_distance = distances.front();
  return true;
}

void Octree::radius_search(const Eigen::Vector3f& query, float radius, std::vector<Eigen::Vector3f>* points,
                           std::vector<float>* squared_distances) const {
  points->clear();
  if (squared_distances) squared_distances->clear();
  if (nodes_.empty() || !query.allFinite() || !(radius >= 0)) return;
  std::vector<std::pair<float, Eigen::Vector3f>> found;
  auto visit = [&](const Eigen::Vector3f& point, float d, float&) { found.emplace_back(d, point); };
  float bound = std::nextafter(radius * radius, std::numeric_limits<float>::infinity());  // within the radius, inclusive
  search(0, query, bound, visit);
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& [d, point] : found) {
    points->push_back(point);
    if (squared_distances) squared_distances->push_back(d);
  }
}

std::vector<Eigen::Vector3f> Octree::points() const {
  std::vector<Eigen::Vector3f> all;
  all.reserve(point_count_);
  for (const Node& node : nodes_) all.insert(all.end(), node.points.begin(), node.points.end());
  return all;
}

std::size_t Octree::memory_bytes() const {
  std::size_t bytes = nodes_.capacity() * sizeof(Node) + free_nodes_.capacity() * sizeof(uint32_t);
  for (const Node& node : nodes_) bytes += node.points.capacity() * sizeof(Eigen::Vector3f);
  return bytes;
}

}  // namespace hanzo::fusion::cloud
