#include "hanzo/fusion/maps/tsdf.hpp"

#include "hanzo/fusion/maps/marching_cubes.hpp"

#include <cmath>
#include <limits>
#include <map>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::maps {
namespace {

using ::testing::HasSubstr;

msgs::CameraIntrinsics small_camera() {
  msgs::CameraIntrinsics intrinsics;
  intrinsics.fx = 120.0;
  intrinsics.fy = 120.0;
  intrinsics.cx = 79.5;
  intrinsics.cy = 59.5;
  intrinsics.width = 160;
  intrinsics.height = 120;
  return intrinsics;
}

/// Camera at `eye` looking at the origin (z forward, x right, y down).
SE3 look_at_origin(const Eigen::Vector3d& eye) {
  const Eigen::Vector3d forward = -eye.normalized();
  const Eigen::Vector3d helper = std::abs(forward.z()) > 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d right = forward.cross(helper).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d rotation;
  rotation << right, down, forward;
  return SE3(SO3::from_matrix(rotation), eye);
}

/// Depth image of a sphere of `radius` at the origin (0 where the ray misses).
std::vector<float> sphere_depth(const SE3& T_world_camera, const msgs::CameraIntrinsics& camera, double radius) {
  std::vector<float> depth(camera.width * camera.height, 0.0f);
  const Eigen::Vector3d eye = T_world_camera.translation();
  for (uint32_t v = 0; v < camera.height; ++v) {
    for (uint32_t u = 0; u < camera.width; ++u) {
      const Eigen::Vector3d ray_camera((u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0);
      const Eigen::Vector3d direction = (T_world_camera.rotation().matrix() * ray_camera).normalized();
      const double b = eye.dot(direction);
      const double discriminant = b * b - (eye.squaredNorm() - radius * radius);
      if (discriminant < 0.0) continue;
      const double distance = -b - std::sqrt(discriminant);
      depth[v * camera.width + u] = static_cast<float>(distance * direction.dot(T_world_camera.rotation().matrix().col(2)));
    }
  }
  return depth;
}

TsdfVolume sphere_volume(double voxel) {
  TsdfVolume volume(TsdfConfig{.voxel_size = voxel});
  const msgs::CameraIntrinsics camera = small_camera();
  // Six views along the axes and eight towards the corners: every surface point is seen at
  // less than 40 deg from its normal (at grazing views the projective distance of voxels just
  // inside exceeds the truncation and they stay unobserved, leaving holes, as in any
  // projective TSDF).
  std::vector<Eigen::Vector3d> eyes{{3, 0, 0}, {-3, 0, 0}, {0, 3, 0}, {0, -3, 0}, {0, 0.5, 3}, {0, -0.5, -3}};
  for (int corner = 0; corner < 8; ++corner) {
    eyes.emplace_back(corner & 1 ? 1.7 : -1.7, corner & 2 ? 1.7 : -1.7, corner & 4 ? 1.7 : -1.7);
  }
  for (const Eigen::Vector3d& eye : eyes) {
    const SE3 pose = look_at_origin(eye);
    const std::vector<float> depth = sphere_depth(pose, camera, 1.0);
    EXPECT_TRUE(volume.integrate_depth({160, 120, depth}, camera, pose));
  }
  return volume;
}

TEST(Tsdf, SphereFromDepthImagesMeshesWithinOneVoxel) {
  const double voxel = 0.05;
  const TsdfVolume volume = sphere_volume(voxel);
  const msgs::MeshLayer mesh = volume.extract_mesh();
  ASSERT_GT(mesh.vertices.size(), 2000u);
  ASSERT_EQ(mesh.triangle_indices.size() % 3, 0u);
  double worst = 0.0;
  for (const Eigen::Vector3f& vertex : mesh.vertices) worst = std::max(worst, std::abs(vertex.cast<double>().norm() - 1.0));
  std::printf("sphere: %zu vertices, %zu triangles, worst radial error %.4f m, %zu blocks\n", mesh.vertices.size(),
              mesh.triangle_indices.size() / 3, worst, volume.block_count());
  EXPECT_LT(worst, voxel);
  // A closed surface: every edge is shared by exactly two triangles (V - E + F = 2).
  std::map<std::pair<uint32_t, uint32_t>, int> edge_uses;
  for (std::size_t t = 0; t < mesh.triangle_indices.size(); t += 3) {
    for (std::size_t k = 0; k < 3; ++k) {
      const uint32_t a = mesh.triangle_indices[t + k];
      const uint32_t b = mesh.triangle_indices[t + (k + 1) % 3];
      ++edge_uses[{std::min(a, b), std::max(a, b)}];
    }
  }
  std::size_t not_shared_by_two = 0;
  for (const auto& [edge, uses] : edge_uses) not_shared_by_two += uses == 2 ? 0 : 1;
  EXPECT_EQ(not_shared_by_two, 0u);
  EXPECT_EQ(static_cast<long>(mesh.vertices.size()) - static_cast<long>(edge_uses.size()) +
                static_cast<long>(mesh.triangle_indices.size() / 3),
            2);
  for (uint32_t index : mesh.triangle_indices) ASSERT_LT(index, mesh.vertices.size());
  // Signs: outside positive, inside negative, unobserved far away.
  EXPECT_GT(volume.sample({1.1, 0.0, 0.0}).first, 0.05f);
  EXPECT_LT(volume.sample({0.9, 0.0, 0.0}).first, -0.05f);
  EXPECT_EQ(volume.sample({5.0, 5.0, 5.0}).second, 0.0f);
}

TEST(MarchingCubes, ASampledSphereMeshesOnItsRadiusAndUnknownSamplesLeaveAHole) {
  // |p| - 0.7 sampled every 0.05 m over [-1, 1]^3 (origin off the lattice of the centre).
  const double spacing = 0.05;
  const Eigen::Vector3d origin(-1.0, -1.01, -0.98);
  const Eigen::Vector3i size(41, 41, 41);
  std::vector<float> values;
  for (int z = 0; z < size.z(); ++z) {
    for (int y = 0; y < size.y(); ++y) {
      for (int x = 0; x < size.x(); ++x) values.push_back(static_cast<float>((origin + spacing * Eigen::Vector3d(x, y, z)).norm() - 0.7));
    }
  }
  const Result<msgs::MeshLayer> mesh = marching_cubes({size, origin, spacing, values});
  ASSERT_TRUE(mesh.ok()) << mesh.error().message;
  ASSERT_GT(mesh->triangle_indices.size(), 3000u);
  for (const Eigen::Vector3f& vertex : mesh->vertices) EXPECT_NEAR(vertex.norm(), 0.7, 0.1 * spacing);
  // Shared vertices: a closed surface has V - E + F = 2 with E = 3F / 2.
  EXPECT_EQ(static_cast<int64_t>(mesh->vertices.size()) - static_cast<int64_t>(mesh->triangle_indices.size()) / 6, 2);
  // The +x half unknown: only the -x half meshes.
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (static_cast<int>(i % 41) > 20) values[i] = std::numeric_limits<float>::quiet_NaN();
  }
  const Result<msgs::MeshLayer> half = marching_cubes({size, origin, spacing, values});
  ASSERT_TRUE(half.ok());
  for (const Eigen::Vector3f& vertex : half->vertices) EXPECT_LE(vertex.x(), origin.x() + 20 * spacing + 1e-6);
  EXPECT_LT(half->triangle_indices.size(), mesh->triangle_indices.size() * 0.6);
  EXPECT_FALSE(marching_cubes({size, origin, spacing, std::span<const float>(values).first(10)}).ok());
  EXPECT_FALSE(marching_cubes({size, origin, 0.0, values}).ok());
}

TEST(Tsdf, PlaneFromARangeScan) {
  TsdfVolume volume(TsdfConfig{.voxel_size = 0.1});
  std::vector<Eigen::Vector3d> points;
  for (double x = -3.0; x <= 3.0; x += 0.05) {
    for (double y = -3.0; y <= 3.0; y += 0.05) points.emplace_back(x, y, 0.0);
  }
  ASSERT_TRUE(volume.integrate_scan(Eigen::Vector3d(0.0, 0.0, 2.0), points));
  const msgs::MeshLayer mesh = volume.extract_mesh();
  ASSERT_GT(mesh.vertices.size(), 500u);
  for (const Eigen::Vector3f& vertex : mesh.vertices) ASSERT_LT(std::abs(vertex.z()), 0.1f) << vertex.transpose();
  // The voxel centred 0.15 m above the plane, right under the sensor: about +0.15 m.
  EXPECT_NEAR(volume.sample({0.05, 0.05, 0.15}).first, 0.15f, 0.02f);
}

TEST(Tsdf, LayerRoundTripKeepsEveryVoxel) {
  const TsdfVolume volume = sphere_volume(0.1);
  const msgs::TsdfLayer layer = volume.to_layer();
  EXPECT_EQ(layer.blocks.size(), volume.block_count());
  EXPECT_NEAR(layer.truncation_distance, 0.3, 1e-12);
  auto restored = TsdfVolume::from_layer(layer);
  ASSERT_TRUE(restored.ok()) << restored.error().message;
  const msgs::MeshLayer a = volume.extract_mesh();
  const msgs::MeshLayer b = restored->extract_mesh();
  EXPECT_EQ(a.vertices, b.vertices);
  EXPECT_EQ(a.triangle_indices, b.triangle_indices);

  msgs::TsdfLayer duplicated = layer;
  duplicated.blocks.push_back(layer.blocks.front());
  EXPECT_THAT(TsdfVolume::from_layer(duplicated).error().message, HasSubstr("appears twice"));
  msgs::TsdfLayer short_block = layer;
  short_block.blocks.front().weights.pop_back();
  EXPECT_FALSE(TsdfVolume::from_layer(short_block).ok());
}

TEST(Tsdf, BadInputIsRejectedAndChangesNothing) {
  TsdfVolume volume(TsdfConfig{.voxel_size = 0.1});
  const std::vector<float> depth(100, 1.0f);
  EXPECT_THAT(volume.integrate_depth({160, 120, depth}, small_camera(), SE3()).error().message, HasSubstr("100 values"));
  msgs::CameraIntrinsics no_focal = small_camera();
  no_focal.fx = 0.0;
  const std::vector<float> full(160 * 120, 1.0f);
  EXPECT_FALSE(volume.integrate_depth({160, 120, full}, no_focal, SE3()));
  std::vector<Eigen::Vector3d> points{{1, 0, 0}, {NAN, 0, 0}};
  EXPECT_EQ(volume.integrate_scan(Eigen::Vector3d::Zero(), points).error().field, "end_points[1]");
  EXPECT_EQ(volume.block_count(), 0u);
  EXPECT_EQ(TsdfVolume::create(TsdfConfig{.voxel_size = 0.0}).error().field, "voxel_size");
  EXPECT_EQ(TsdfVolume::create(TsdfConfig{.block_size = 1}).error().field, "block_size");
}

}  // namespace
}  // namespace hanzo::fusion::maps
