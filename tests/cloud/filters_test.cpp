// Kd-tree against brute force; voxel grid, outlier removal, ground segmentation and local
// geometry on clouds with known answers.

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "hanzo/fusion/cloud/ground_segmentation.hpp"
#include "hanzo/fusion/cloud/kdtree.hpp"
#include "hanzo/fusion/cloud/local_geometry.hpp"
#include "hanzo/fusion/cloud/outlier_removal.hpp"
#include "hanzo/fusion/cloud/voxel_grid.hpp"

namespace hanzo::fusion::cloud {
namespace {

std::vector<Eigen::Vector3f> random_points(size_t count, float extent, uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> uniform(-extent, extent);
  std::vector<Eigen::Vector3f> points(count);
  for (auto& p : points) p = Eigen::Vector3f(uniform(random), uniform(random), uniform(random));
  return points;
}

TEST(KdTree, MatchesBruteForce) {
  const auto points = random_points(2000, 5.0f, 1);
  const KdTree tree(points);
  for (const auto& query : random_points(100, 6.0f, 2)) {
    std::vector<std::pair<float, uint32_t>> all;
    for (uint32_t i = 0; i < points.size(); ++i) all.emplace_back((points[i] - query).squaredNorm(), i);
    std::sort(all.begin(), all.end());
    uint32_t indices[5];
    float distances[5];
    ASSERT_EQ(tree.knn(query, 5, indices, distances), 5u);
    for (int k = 0; k < 5; ++k) EXPECT_EQ(indices[k], all[k].second);
    uint32_t nearest = 0;
    float distance = 0.0f;
    const bool found = tree.nearest(query, 0.25f, &nearest, &distance);
    EXPECT_EQ(found, all[0].first < 0.25f);
    if (found) {
      EXPECT_EQ(nearest, all[0].second);
    }
    std::vector<uint32_t> within;
    std::vector<float> within_distances;
    tree.radius_search(query, 1.0f, &within, &within_distances);
    const auto expected = std::count_if(all.begin(), all.end(), [](const auto& a) { return a.first < 1.0f; });
    EXPECT_EQ(static_cast<long>(within.size()), expected);
    EXPECT_EQ(static_cast<long>(tree.count_within(query, 1.0f, 1000)), expected);
  }
  const KdTree empty(std::vector<Eigen::Vector3f>{});
  uint32_t index = 0;
  float distance = 0.0f;
  EXPECT_FALSE(empty.nearest(Eigen::Vector3f::Zero(), 1.0f, &index, &distance));
}

TEST(VoxelGrid, OnePointPerVoxelAtTheCentroid) {
  PointCloud cloud;
  // Two points in voxel (0,0,0) and one in voxel (1,0,0) at 1 m.
  cloud.positions = {{0.2f, 0.2f, 0.2f}, {0.4f, 0.6f, 0.8f}, {1.5f, 0.5f, 0.5f}};
  cloud.intensities = {1.0f, 3.0f, 5.0f};
  const PointCloud down = voxel_downsample(cloud, 1.0);
  ASSERT_EQ(down.size(), 2u);
  EXPECT_TRUE(down.positions[0].isApprox(Eigen::Vector3f(0.3f, 0.4f, 0.5f)));
  EXPECT_FLOAT_EQ(down.intensities[0], 2.0f);
  EXPECT_FLOAT_EQ(down.intensities[1], 5.0f);

  // The result does not depend on the thread count.
  PointCloud big;
  big.positions = random_points(50000, 10.0f, 3);
  const PointCloud one = voxel_downsample(big, 0.5, 1);
  const PointCloud two = voxel_downsample(big, 0.5, 2);
  EXPECT_EQ(one.positions, two.positions);
  EXPECT_LE(one.size(), 40u * 40u * 40u);
  EXPECT_GT(one.size(), 30000u);  // 50k points over 64k voxels: most voxels hold one point
}

TEST(VoxelGrid, FirstPointPerVoxelKeepsTheFirstCandidateOfEachVoxelInOrder) {
  // floor, not truncation, below zero: -0.1 and -0.9 share voxel -1; -1.0 is voxel -1 too, -1.01
  // voxel -2; far coordinates beyond the key range (+-2^20 voxels) are dropped.
  EXPECT_EQ(floor_to_int(-0.1F), -1);
  EXPECT_EQ(floor_to_int(-1.0F), -1);
  EXPECT_EQ(floor_to_int(-1.01F), -2);
  EXPECT_EQ(floor_to_int(2.99F), 2);
  EXPECT_EQ(floor_to_int(1e20F), 1073741824);
  const std::vector<Eigen::Vector3f> points = {{-0.1F, 0.5F, 0.5F}, {0.1F, 0.5F, 0.5F}, {-0.9F, 0.2F, 0.7F}, {5e6F, 0.0F, 0.0F},
                                               {0.9F, 0.9F, 0.9F},  {-1.01F, 0.5F, 0.5F}, {-1.0F, 0.5F, 0.5F}};
  EXPECT_EQ(first_point_per_voxel(points, {0, 1, 2, 3, 4, 5, 6}, 1.0), (std::vector<uint32_t>{0, 1, 5}));
  // Candidates in another order: the first of them per voxel.
  EXPECT_EQ(first_point_per_voxel(points, {6, 4, 2, 0}, 1.0), (std::vector<uint32_t>{6, 4}));

  // Against a plain set over many points (the small recent-key table must not change the answer).
  const std::vector<Eigen::Vector3f> many = random_points(50000, 10.0f, 5);
  std::vector<uint32_t> all(many.size());
  for (uint32_t i = 0; i < all.size(); ++i) all[i] = i;
  std::set<std::array<int, 3>> seen;
  std::vector<uint32_t> expected;
  for (uint32_t i = 0; i < many.size(); ++i) {
    const Eigen::Vector3f scaled = many[i] * static_cast<float>(1.0 / 0.7);
    if (seen.insert({static_cast<int>(std::floor(scaled.x())), static_cast<int>(std::floor(scaled.y())), static_cast<int>(std::floor(scaled.z()))}).second) {
      expected.push_back(i);
    }
  }
  EXPECT_EQ(first_point_per_voxel(many, all, 0.7), expected);
  // On several threads chunks of candidates are merged in order: the same points.
  EXPECT_EQ(first_point_per_voxel(many, all, 0.7, 2), expected);
  EXPECT_EQ(first_point_per_voxel(many, all, 0.7, 3), expected);
}

TEST(OutlierRemoval, DropsIsolatedPoints) {
  PointCloud cloud;
  cloud.positions = random_points(3000, 1.0f, 4);   // dense cube
  cloud.positions.emplace_back(10.0f, 0.0f, 0.0f);  // isolated
  cloud.positions.emplace_back(0.0f, 10.0f, 0.0f);
  const auto kept = inlier_indices(cloud, OutlierRemovalConfig{});
  EXPECT_EQ(kept.size(), 3000u);
  EXPECT_EQ(kept.back(), 2999u);
}

TEST(GroundSegmentation, FindsTheFloorNotTheWall) {
  std::mt19937 random(5);
  std::uniform_real_distribution<float> uniform(-10.0f, 10.0f);
  std::normal_distribution<float> noise(0.0f, 0.02f);
  PointCloud cloud;
  for (int i = 0; i < 4000; ++i) cloud.positions.emplace_back(uniform(random), uniform(random), -1.7f + noise(random));  // floor
  for (int i = 0; i < 6000; ++i) cloud.positions.emplace_back(5.0f + noise(random), uniform(random), uniform(random) * 0.2f + 1.0f);  // wall
  const GroundSegmentation ground = segment_ground(cloud);
  ASSERT_TRUE(ground.found) << ground.message;
  EXPECT_NEAR(ground.normal.z(), 1.0, 1e-3);
  EXPECT_NEAR(ground.offset, 1.7, 0.01);
  EXPECT_NEAR(static_cast<double>(ground.ground.size()), 4000.0, 40.0);
  EXPECT_EQ(ground.ground.size() + ground.obstacles.size(), cloud.size());

  PointCloud wall_only;
  for (int i = 0; i < 1000; ++i) wall_only.positions.emplace_back(5.0f, uniform(random), uniform(random));
  const GroundSegmentation none = segment_ground(wall_only);
  EXPECT_FALSE(none.found);
  EXPECT_FALSE(none.message.empty());
  EXPECT_EQ(none.obstacles.size(), 1000u);
}

TEST(LocalGeometry, PlaneGivesItsNormalAndAFlatCovariance) {
  std::mt19937 random(6);
  std::uniform_real_distribution<float> uniform(-2.0f, 2.0f);
  PointCloud cloud;
  const Eigen::Vector3f normal = Eigen::Vector3f(0.2f, -0.3f, 1.0f).normalized();
  const Eigen::Vector3f u = normal.unitOrthogonal();
  const Eigen::Vector3f v = normal.cross(u);
  const Eigen::Vector3f offset = normal * 3.0f;  // the plane passes 3 m from the origin
  for (int i = 0; i < 2000; ++i) cloud.positions.push_back(offset + uniform(random) * u + uniform(random) * v);
  LocalGeometryConfig config;
  config.num_threads = 2;
  estimate_local_geometry(cloud, config);
  ASSERT_EQ(cloud.normals.size(), cloud.size());
  for (size_t i = 0; i < cloud.size(); i += 50) {
    EXPECT_GT(cloud.normals[i].dot(-normal), 0.999f);  // oriented toward the origin
    EXPECT_NEAR(normal.dot(cloud.covariances[i] * normal), 1e-3f, 1e-4f);
    EXPECT_NEAR(u.dot(cloud.covariances[i] * u), 1.0f, 1e-3f);
  }
}

}  // namespace
}  // namespace hanzo::fusion::cloud
