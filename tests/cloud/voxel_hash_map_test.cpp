// VoxelHashMap (insertion rules, removal, exact neighbour queries) and the range-image normals
// of cloud/scan_normals.hpp on synthetic ring scans.

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/cloud/scan_normals.hpp"
#include "hanzo/fusion/cloud/voxel_hash_map.hpp"

namespace hanzo::fusion::cloud {
namespace {

std::vector<Eigen::Vector3f> random_points(std::size_t count, float extent, uint32_t seed) {
  std::mt19937 random(seed);
  std::uniform_real_distribution<float> uniform(-extent, extent);
  std::vector<Eigen::Vector3f> points(count);
  for (Eigen::Vector3f& p : points) p = Eigen::Vector3f(uniform(random), uniform(random), uniform(random));
  return points;
}

TEST(VoxelHashMap, KeepsAtMostMaxPointsPerVoxelAndTheirSpacing) {
  VoxelHashMap map({.voxel_size = 1.0, .max_points_per_voxel = 5, .min_point_spacing = 0.2, .max_distance = 100.0});
  // 200 points in one voxel [0, 1)^3.
  std::vector<Eigen::Vector3f> points = random_points(200, 0.5F, 1);
  for (Eigen::Vector3f& p : points) p += Eigen::Vector3f::Constant(0.5F);
  map.add(points, {}, Eigen::Vector3d::Zero());
  ASSERT_EQ(map.voxel_count(), 1U);
  EXPECT_EQ(map.point_count(), 5U);
  const std::vector<MapPoint>* voxel = map.find(Eigen::Vector3i::Zero());
  ASSERT_NE(voxel, nullptr);
  for (std::size_t a = 0; a < voxel->size(); ++a) {
    for (std::size_t b = a + 1; b < voxel->size(); ++b) EXPECT_GE(((*voxel)[a].position - (*voxel)[b].position).norm(), 0.2F);
  }
  // A point too close to a kept one is refused even in a voxel with room.
  VoxelHashMap spaced({.voxel_size = 1.0, .max_points_per_voxel = 20, .min_point_spacing = 0.2, .max_distance = 100.0});
  spaced.add({Eigen::Vector3f(0.5F, 0.5F, 0.5F), Eigen::Vector3f(0.55F, 0.5F, 0.5F), Eigen::Vector3f(0.8F, 0.5F, 0.5F)}, {},
             Eigen::Vector3d::Zero());
  EXPECT_EQ(spaced.point_count(), 2U);
}

TEST(VoxelHashMap, AddsTheSamePointsInTheSameOrderOnSeveralThreads) {
  // Three overlapping scans into maps on 1, 2 and 3 threads: the candidates checked in parallel
  // against the map as it stands, then in order against this scan's own points, must give the
  // sequential result point for point (normals carry each point's index to check which was kept).
  const VoxelHashMapConfig config{.voxel_size = 0.5, .max_points_per_voxel = 8, .min_point_spacing = -1.0, .max_distance = 100.0};
  std::vector<VoxelHashMap> maps(3, VoxelHashMap(config));
  for (uint32_t scan = 0; scan < 3; ++scan) {
    std::vector<Eigen::Vector3f> points = random_points(20000, 4.0F, 10 + scan);
    points[123] = Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN());
    for (std::size_t threads = 1; threads <= maps.size(); ++threads) {
      maps[threads - 1].add(points, Eigen::Vector3d::Zero(),
                            [&](std::size_t i) { return Eigen::Vector3f(static_cast<float>(scan), static_cast<float>(i), 0.0F); },
                            static_cast<int>(threads));
    }
  }
  ASSERT_GT(maps[0].point_count(), 10000U);
  ASSERT_LT(maps[0].point_count(), 3 * 20000U);
  EXPECT_EQ(maps[0].skipped_points(), 3U);
  for (std::size_t threads = 2; threads <= maps.size(); ++threads) {
    const VoxelHashMap& map = maps[threads - 1];
    EXPECT_EQ(map.point_count(), maps[0].point_count());
    EXPECT_EQ(map.voxel_count(), maps[0].voxel_count());
    EXPECT_EQ(map.skipped_points(), maps[0].skipped_points());
    for (const Eigen::Vector3f& position : maps[0].points()) {
      const std::vector<MapPoint>* expected = maps[0].find(maps[0].coordinates(position));
      const std::vector<MapPoint>* actual = map.find(map.coordinates(position));
      ASSERT_NE(actual, nullptr);
      ASSERT_EQ(actual->size(), expected->size());
      for (std::size_t k = 0; k < expected->size(); ++k) {
        EXPECT_EQ((*actual)[k].position, (*expected)[k].position);
        EXPECT_EQ((*actual)[k].normal, (*expected)[k].normal);
      }
    }
  }
}

TEST(VoxelHashMap, DropsVoxelsBeyondMaxDistanceAndNonFinitePoints) {
  VoxelHashMap map({.voxel_size = 1.0, .max_points_per_voxel = 20, .min_point_spacing = 0.0, .max_distance = 10.0});
  const float nan = std::numeric_limits<float>::quiet_NaN();
  map.add({Eigen::Vector3f(1, 0, 0), Eigen::Vector3f(5, 0, 0), Eigen::Vector3f(9.5F, 0, 0), Eigen::Vector3f(nan, 0, 0)},
          {}, Eigen::Vector3d::Zero());
  EXPECT_EQ(map.point_count(), 3U);
  EXPECT_EQ(map.skipped_points(), 1U);
  // The sensor moved 8 m along -x: the points at 5 and 9.5 m are now 13 and 17.5 m away.
  map.add({}, {}, Eigen::Vector3d(-8, 0, 0));
  EXPECT_EQ(map.point_count(), 1U);
  EXPECT_EQ(map.voxel_count(), 1U);
  EXPECT_GT(map.memory_bytes(), 0U);
}

TEST(VoxelHashMap, NeighbourQueriesAreExactWithinOneVoxel) {
  VoxelHashMap map({.voxel_size = 0.5, .max_points_per_voxel = 1000, .min_point_spacing = 0.0, .max_distance = 100.0});
  const std::vector<Eigen::Vector3f> points = random_points(3000, 2.0F, 2);
  std::vector<Eigen::Vector3f> normals(points.size(), Eigen::Vector3f::UnitZ());
  map.add(points, normals, Eigen::Vector3d::Zero());
  ASSERT_EQ(map.point_count(), points.size());
  std::vector<MapPoint> found;
  for (const Eigen::Vector3f& query : random_points(200, 1.8F, 3)) {
    std::vector<std::pair<float, int>> brute;
    for (std::size_t i = 0; i < points.size(); ++i) brute.emplace_back((points[i] - query).norm(), static_cast<int>(i));
    std::sort(brute.begin(), brute.end());
    Eigen::Vector3f nearest_point;
    float squared = 0.0F;
    ASSERT_TRUE(map.nearest(query, &nearest_point, &squared));
    EXPECT_FLOAT_EQ(std::sqrt(squared), brute[0].first);
    map.nearest_k(query, 8, 0.5F, &found);
    std::size_t expected = 0;
    while (expected < 8 && brute[expected].first < 0.5F) ++expected;
    ASSERT_EQ(found.size(), expected);
    for (std::size_t k = 0; k < found.size(); ++k) {
      EXPECT_FLOAT_EQ((found[k].position - query).norm(), brute[k].first);
      EXPECT_EQ(found[k].normal, Eigen::Vector3f::UnitZ());
    }
  }
  const std::vector<Eigen::Vector3f> far = {Eigen::Vector3f(50, 50, 50)};
  Eigen::Vector3f point;
  float squared = 0.0F;
  EXPECT_FALSE(map.nearest(far[0], &point, &squared));
}

// A 32-ring sensor at the origin, 1 m above a floor, 6 m from a wall x = 6 (sensor frame).
PointCloud ring_scan() {
  PointCloud scan;
  const int rings = 32, columns = 1024;
  for (int c = 0; c < columns; ++c) {
    const double azimuth = -M_PI + 2.0 * M_PI * (c + 0.5) / columns;
    for (int r = 0; r < rings; ++r) {
      const double elevation = (-25.0 + 40.0 * r / (rings - 1)) * M_PI / 180.0;
      const Eigen::Vector3d direction(std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
      double range = std::numeric_limits<double>::infinity();
      if (direction.z() < 0) range = std::min(range, -1.0 / direction.z());
      if (direction.x() > 0) range = std::min(range, 6.0 / direction.x());
      if (!(range < 40.0)) continue;
      scan.positions.push_back((direction * range).cast<float>());
      scan.rings.push_back(static_cast<uint16_t>(r));
    }
  }
  return scan;
}

TEST(ScanNormals, FloorAndWallNormalsFromAdjacentRingsPointAtTheSensor) {
  const PointCloud scan = ring_scan();
  const std::vector<Eigen::Vector3f> normals = estimate_scan_normals(scan);
  ASSERT_EQ(normals.size(), scan.size());
  std::size_t floor = 0, wall = 0, floor_good = 0, wall_good = 0;
  for (std::size_t i = 0; i < scan.size(); ++i) {
    const Eigen::Vector3f& p = scan.positions[i];
    if (normals[i].isZero()) continue;
    EXPECT_NEAR(normals[i].norm(), 1.0F, 1e-4F);
    EXPECT_LT(normals[i].dot(p), 0.0F) << "normals face the sensor";
    // Away from the floor-wall corner, each surface's normal is its plane's.
    if (std::abs(p.z() + 1.0F) < 1e-3F && p.x() < 5.0F) {
      ++floor;
      floor_good += normals[i].z() > std::cos(2.0 * M_PI / 180.0) ? 1 : 0;
    } else if (std::abs(p.x() - 6.0F) < 1e-3F && p.z() > -0.5F) {
      ++wall;
      wall_good += -normals[i].x() > std::cos(2.0 * M_PI / 180.0) ? 1 : 0;
    }
  }
  EXPECT_GT(floor, 1000U);
  EXPECT_GT(wall, 1000U);
  // Within 2 degrees; the few others sit where a neighbourhood spans the seam of the azimuth bins
  // or reaches around the corner and still passes the planarity test.
  EXPECT_GT(static_cast<double>(floor_good), 0.995 * static_cast<double>(floor));
  EXPECT_GT(static_cast<double>(wall_good), 0.995 * static_cast<double>(wall));
  // A subset gets the same normals as the whole scan.
  const std::vector<uint32_t> subset = {0, 7, 100, static_cast<uint32_t>(scan.size() - 1)};
  const std::vector<Eigen::Vector3f> some = estimate_scan_normals(scan, subset);
  for (std::size_t n = 0; n < subset.size(); ++n) EXPECT_EQ(some[n], normals[subset[n]]);
}

TEST(ScanNormals, TheRangeImageKeepsEachCellsFirstPointOnAnyNumberOfThreads) {
  // Second returns 0.7 m behind every third point, appended after the whole sweep (in another
  // thread's chunk than their first returns): each cell must keep its first return.
  PointCloud scan = ring_scan();
  const std::size_t first_returns = scan.size();
  for (std::size_t i = 0; i < first_returns; i += 3) {
    scan.positions.push_back(scan.positions[i] * (1.0F + 0.7F / scan.positions[i].norm()));
    scan.rings.push_back(scan.rings[i]);
  }
  const ScanNormalEstimator one_thread(scan, {}, 1);
  std::size_t with_normal = 0;
  for (std::size_t i = 0; i < first_returns; ++i) with_normal += one_thread.normal(i).isZero() ? 0 : 1;
  EXPECT_GT(with_normal, first_returns / 2);
  for (int threads : {2, 3}) {
    const ScanNormalEstimator several(scan, {}, threads);
    for (std::size_t i = 0; i < scan.size(); ++i) {
      ASSERT_EQ(several.normal(i), one_thread.normal(i)) << "point " << i << " on " << threads << " threads";
      ASSERT_EQ(several.isolated(i, 0.3F), one_thread.isolated(i, 0.3F)) << "point " << i << " on " << threads << " threads";
    }
  }
}

TEST(ScanNormals, NoRingsOrIsolatedRingsGiveNoNormal) {
  PointCloud scan = ring_scan();
  PointCloud without_rings = scan;
  without_rings.rings.clear();
  for (const Eigen::Vector3f& n : estimate_scan_normals(without_rings)) EXPECT_TRUE(n.isZero());
  // Every fourth ring only: no ring has a ring index next to it, so no point has neighbours on
  // another ring (a lone ring is a line: its plane is undetermined).
  PointCloud sparse;
  for (std::size_t i = 0; i < scan.size(); ++i) {
    if (scan.rings[i] % 4 != 0) continue;
    sparse.positions.push_back(scan.positions[i]);
    sparse.rings.push_back(scan.rings[i]);
  }
  for (const Eigen::Vector3f& n : estimate_scan_normals(sparse)) EXPECT_TRUE(n.isZero());
}

}  // namespace
}  // namespace hanzo::fusion::cloud
