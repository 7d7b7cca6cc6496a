// Octree: every query answered exactly as a brute-force search over the same points, after
// insertions that grow the root, splits, spacing refusals and removals around a moving centre.

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/cloud/octree.hpp"

namespace hanzo::fusion::cloud {
namespace {

// A ground plane, a wall and scattered clutter around `origin`.
std::vector<Eigen::Vector3f> scene(std::size_t count, const Eigen::Vector3f& origin, uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> unit(-1.0F, 1.0F);
  std::vector<Eigen::Vector3f> points;
  for (std::size_t i = 0; i < count; ++i) {
    const float u = 30.0F * unit(random), v = 30.0F * unit(random);
    switch (i % 3) {
      case 0: points.emplace_back(u, v, 0.01F * unit(random)); break;      // ground
      case 1: points.emplace_back(12.0F, u, 3.0F + 3.0F * unit(random)); break;  // wall
      default: points.emplace_back(u, v, 5.0F + 5.0F * unit(random)); break;     // clutter
    }
    points.back() += origin;
  }
  return points;
}

std::vector<float> brute_force_distances(const std::vector<Eigen::Vector3f>& points, const Eigen::Vector3f& query) {
  std::vector<float> distances;
  for (const Eigen::Vector3f& p : points) distances.push_back((p - query).squaredNorm());
  std::sort(distances.begin(), distances.end());
  return distances;
}

void expect_queries_exact(const Octree& tree, const std::vector<Eigen::Vector3f>& reference, uint32_t seed) {
  ASSERT_EQ(tree.size(), reference.size());
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> unit(-40.0F, 40.0F);
  std::vector<Eigen::Vector3f> found;
  std::vector<float> distances;
  for (int q = 0; q < 200; ++q) {
    const Eigen::Vector3f query(unit(random), unit(random), 0.2F * unit(random));
    const std::vector<float> expected = brute_force_distances(reference, query);
    tree.knn(query, 10, &found, &distances);
    ASSERT_EQ(found.size(), std::min<std::size_t>(10, reference.size()));
    for (std::size_t i = 0; i < found.size(); ++i) {
      EXPECT_EQ(distances[i], expected[i]) << "query " << q << " neighbour " << i;
      EXPECT_EQ((found[i] - query).squaredNorm(), distances[i]);
    }
    tree.radius_search(query, 2.0F, &found, &distances);
    const auto within = static_cast<std::size_t>(std::upper_bound(expected.begin(), expected.end(), 4.0F) - expected.begin());
    ASSERT_EQ(found.size(), within) << "query " << q;
    for (std::size_t i = 0; i < within; ++i) EXPECT_EQ(distances[i], expected[i]);
    Eigen::Vector3f nearest;
    float nearest_distance = 0.0F;
    const bool any = tree.nearest(query, 1.0F, &nearest, &nearest_distance);
    EXPECT_EQ(any, !expected.empty() && expected.front() < 1.0F);
    if (any) {
      EXPECT_EQ(nearest_distance, expected.front());
    }
  }
}

TEST(Octree, QueriesMatchBruteForceAfterGrowingSplittingAndRemoving) {
  Octree tree(OctreeConfig{.bucket_size = 16, .min_leaf_size = 0.05, .min_point_spacing = 0.0, .initial_size = 4.0});
  std::vector<Eigen::Vector3f> reference = scene(20000, Eigen::Vector3f::Zero(), 1);
  EXPECT_EQ(tree.insert(reference), reference.size());  // the 4 m root grows to hold 60 m
  EXPECT_GT(tree.node_count(), 1000U);
  expect_queries_exact(tree, reference, 2);

  // The sensor moves on: a new batch 20 m away, then everything beyond 35 m of it goes.
  const Eigen::Vector3f moved(20.0F, 5.0F, 0.0F);
  const std::vector<Eigen::Vector3f> batch = scene(10000, moved, 3);
  tree.insert(batch);
  reference.insert(reference.end(), batch.begin(), batch.end());
  const std::size_t before = reference.size();
  std::erase_if(reference, [&](const Eigen::Vector3f& p) { return (p - moved).squaredNorm() > 35.0F * 35.0F; });
  EXPECT_EQ(tree.remove_outside(moved, 35.0F), before - reference.size());
  expect_queries_exact(tree, reference, 4);
  std::vector<Eigen::Vector3f> held = tree.points();
  EXPECT_EQ(held.size(), reference.size());

  // Removing everything frees the nodes; the tree still works afterwards.
  EXPECT_EQ(tree.remove_outside(Eigen::Vector3f(1e4F, 0.0F, 0.0F), 1.0F), reference.size());
  EXPECT_TRUE(tree.empty());
  EXPECT_EQ(tree.node_count(), 1U);
  reference = scene(3000, Eigen::Vector3f(-50.0F, 0.0F, 0.0F), 5);
  tree.insert(reference);
  expect_queries_exact(tree, reference, 6);
}

TEST(Octree, KeepsOnePointPerSpacingAndBoundsDenseLeaves) {
  Octree tree(OctreeConfig{.bucket_size = 8, .min_leaf_size = 0.5, .min_point_spacing = 0.1});
  // 1000 copies of nearly the same point: one is kept.
  std::vector<Eigen::Vector3f> same(1000, Eigen::Vector3f(1.0F, 2.0F, 3.0F));
  for (std::size_t i = 0; i < same.size(); ++i) same[i].x() += 1e-5F * static_cast<float>(i);
  EXPECT_EQ(tree.insert(same), 1U);
  // A 1 m grid at 0.05 m: leaves stop splitting at 0.5 m and the spacing rule keeps ~0.1 m.
  std::vector<Eigen::Vector3f> dense;
  for (int i = 0; i < 20; ++i) {
    for (int j = 0; j < 20; ++j) dense.emplace_back(5.0F + 0.05F * static_cast<float>(i), 5.0F + 0.05F * static_cast<float>(j), 0.0F);
  }
  const std::size_t inserted = tree.insert(dense);
  EXPECT_LT(inserted, 200U);
  EXPECT_GT(inserted, 50U);
  const std::vector<Eigen::Vector3f> held = tree.points();
  for (std::size_t a = 0; a < held.size(); ++a) {
    for (std::size_t b = a + 1; b < held.size(); ++b) {
      // Points in different leaves may be closer than the spacing; in the same leaf they are not.
      if ((held[a] - held[b]).norm() < 0.1F) {
        EXPECT_NE(std::floor(held[a].x() / 0.5F) + 100 * std::floor(held[a].y() / 0.5F),
                  std::floor(held[b].x() / 0.5F) + 100 * std::floor(held[b].y() / 0.5F));
      }
    }
  }
}

TEST(Octree, BadInputIsSkippedAndCounted) {
  EXPECT_FALSE(OctreeConfig{.bucket_size = 0}.validate());
  EXPECT_FALSE(OctreeConfig{.min_leaf_size = -1.0}.validate());
  EXPECT_FALSE(OctreeConfig{.min_point_spacing = -0.1}.validate());
  EXPECT_FALSE(OctreeConfig{.initial_size = std::numeric_limits<double>::infinity()}.validate());
  const Octree defaults(OctreeConfig{.bucket_size = 0});
  EXPECT_EQ(defaults.config().bucket_size, OctreeConfig{}.bucket_size);

  Octree tree;
  std::vector<Eigen::Vector3f> found;
  tree.knn(Eigen::Vector3f::Zero(), 5, &found);  // empty tree
  EXPECT_TRUE(found.empty());
  const float nan = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(tree.insert({Eigen::Vector3f(nan, 0, 0), Eigen::Vector3f(1, 1, 1), Eigen::Vector3f(1e9F, 0, 0)}), 1U);
  EXPECT_EQ(tree.skipped_points(), 2U);
  tree.knn(Eigen::Vector3f(nan, 0, 0), 5, &found);
  EXPECT_TRUE(found.empty());
  tree.knn(Eigen::Vector3f::Zero(), 0, &found);
  EXPECT_TRUE(found.empty());
  tree.knn(Eigen::Vector3f::Zero(), 5, &found, nullptr, 1.0F);  // the point is sqrt(3) away
  EXPECT_TRUE(found.empty());
  tree.knn(Eigen::Vector3f::Zero(), 5, &found);
  ASSERT_EQ(found.size(), 1U);
  EXPECT_EQ(found[0], Eigen::Vector3f(1, 1, 1));
  EXPECT_GT(tree.memory_bytes(), 0U);
}

}  // namespace
}  // namespace hanzo::fusion::cloud
