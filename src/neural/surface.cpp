#include "hanzo/fusion/neural/surface.hpp"

#include <vector>

#include <fmt/format.h>

#include "hanzo/fusion/maps/marching_cubes.hpp"

namespace hanzo::fusion::neural {

Result<msgs::MeshLayer> extract_surface(const NerfField& field, const NerfSurfaceConfig& config) {
  if (config.resolution < 2 || config.resolution > 1024) return Error(fmt::format("surface: resolution {} (expected 2 to 1024)", config.resolution));
  if (!(config.density_threshold > 0.0f)) return Error(fmt::format("surface: density_threshold {} (expected > 0)", config.density_threshold));
  const int n = config.resolution;
  const double step = 1.0 / (n - 1);  // unit-cube lengths between samples
  // threshold - density: negative inside; empty cells keep density 0.
  std::vector<float> values(static_cast<std::size_t>(n) * n * n, config.density_threshold);
  std::vector<float> positions;
  std::vector<std::size_t> indices;
  std::vector<float> densities;
  const auto flush = [&] {
    densities.resize(indices.size());
    field.density(positions.data(), indices.size(), densities.data());
    for (std::size_t i = 0; i < indices.size(); ++i) values[indices[i]] = config.density_threshold - densities[i];
    positions.clear();
    indices.clear();
  };
  constexpr std::size_t kBatch = std::size_t{1} << 16;
  std::size_t index = 0;
  for (int z = 0; z < n; ++z) {
    for (int y = 0; y < n; ++y) {
      for (int x = 0; x < n; ++x, ++index) {
        const Eigen::Vector3f unit(static_cast<float>(x * step), static_cast<float>(y * step), static_cast<float>(z * step));
        if (!field.occupancy().occupied(unit)) continue;
        positions.insert(positions.end(), {unit.x(), unit.y(), unit.z()});
        indices.push_back(index);
        if (indices.size() == kBatch) flush();
      }
    }
  }
  if (!indices.empty()) flush();
  // Unit cube [0, 1]^3 onto the scene box.
  const NerfFieldConfig& box = field.config();
  const double scale = field.unit_to_scene_length();
  const Eigen::Vector3d origin = box.box_centre - Eigen::Vector3d::Constant(box.box_half_size);
  return maps::marching_cubes({Eigen::Vector3i::Constant(n), origin, scale * step, values});
}

Result<maps::TsdfVolume> fuse_rendered_depth(const SceneRenderer& render, const std::vector<PosedView>& views, const DepthFusionConfig& config) {
  maps::TsdfConfig tsdf;
  tsdf.voxel_size = config.voxel_size;
  Result<maps::TsdfVolume> volume = maps::TsdfVolume::create(tsdf);
  if (!volume) return Error(fmt::format("depth fusion: {}", volume.error().message));
  for (const PosedView& view : views) {
    NerfRender rendered = render(view.camera);
    if (rendered.width != view.camera.width || rendered.height != view.camera.height ||
        rendered.depth.size() != static_cast<std::size_t>(rendered.width) * static_cast<std::size_t>(rendered.height)) {
      return Error(fmt::format("depth fusion: {}: a {} x {} render for a {} x {} camera", view.name, rendered.width, rendered.height, view.camera.width,
                               view.camera.height));
    }
    for (std::size_t i = 0; i < rendered.depth.size(); ++i) {
      if (rendered.opacity.empty() || rendered.opacity[i] < config.min_opacity) rendered.depth[i] = 0.0f;
    }
    msgs::CameraIntrinsics intrinsics;
    intrinsics.fx = view.camera.fx;
    intrinsics.fy = view.camera.fy;
    intrinsics.cx = view.camera.cx;
    intrinsics.cy = view.camera.cy;
    intrinsics.width = static_cast<uint32_t>(rendered.width);
    intrinsics.height = static_cast<uint32_t>(rendered.height);
    const SE3 T_world_camera = SE3(SO3::from_matrix(view.camera.R_camera_world), view.camera.t_camera_world).inverse();
    if (Status integrated = volume->integrate_depth({rendered.width, rendered.height, rendered.depth}, intrinsics, T_world_camera); !integrated) {
      return Error(fmt::format("depth fusion: {}: {}", view.name, integrated.error().message));
    }
  }
  return volume;
}

}  // namespace hanzo::fusion::neural
