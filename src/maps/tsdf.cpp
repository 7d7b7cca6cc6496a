#include "hanzo/fusion/maps/tsdf.hpp"

#include <algorithm>
#include <cmath>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <fmt/format.h>

#include "layer_checks.hpp"
#include "tsdf_storage.hpp"

namespace hanzo::fusion::maps {

Status TsdfConfig::validate() const {
  if (!(std::isfinite(voxel_size) && voxel_size > 0.0)) {
    return Error{fmt::format("tsdf.voxel_size: must be a positive number of meters, got {}", voxel_size), "voxel_size"};
  }
  if (!(std::isfinite(truncation_distance) && truncation_distance >= 0.0)) {
    return Error{fmt::format("tsdf.truncation_distance: must be >= 0 meters (0: 3 voxels), got {}", truncation_distance),
                 "truncation_distance"};
  }
  if (block_size < 2 || block_size > 32) {
    return Error{fmt::format("tsdf.block_size: must be 2 to 32 voxels, got {}", block_size), "block_size"};
  }
  if (!(std::isfinite(max_weight) && max_weight >= 1.0f && max_weight <= 65535.0f)) {
    return Error{fmt::format("tsdf.max_weight: must be 1 to 65535, got {}", max_weight), "max_weight"};
  }
  if (depth_allocation_stride < 1) {
    return Error{fmt::format("tsdf.depth_allocation_stride: must be >= 1, got {}", depth_allocation_stride), "depth_allocation_stride"};
  }
  if (!(std::isfinite(min_range) && min_range >= 0.0 && std::isfinite(max_range) && max_range >= 0.0)) {
    return Error{"tsdf: min_range and max_range must be >= 0 meters", "min_range"};
  }
  return ok_status();
}

TsdfVolume::TsdfVolume(const TsdfConfig& config) : config_(config), storage_(std::make_unique<TsdfStorage>(config)) {}

Result<TsdfVolume> TsdfVolume::create(const TsdfConfig& config) {
  HANZO_RETURN_IF_ERROR(config.validate());
  return TsdfVolume(config);
}

TsdfVolume::~TsdfVolume() = default;
TsdfVolume::TsdfVolume(TsdfVolume&&) noexcept = default;
TsdfVolume& TsdfVolume::operator=(TsdfVolume&&) noexcept = default;

namespace {

bool in_range(double range, const TsdfConfig& config) {
  return range > config.min_range && (config.max_range <= 0.0 || range <= config.max_range);
}

}  // namespace

Status TsdfVolume::integrate_depth(const DepthImageView& depth, const msgs::CameraIntrinsics& intrinsics, const SE3& T_world_camera) {
  if (depth.width <= 0 || depth.height <= 0 ||
      depth.meters.size() != static_cast<std::size_t>(depth.width) * static_cast<std::size_t>(depth.height)) {
    return Error{fmt::format("depth image: {} values for {} x {} pixels", depth.meters.size(), depth.width, depth.height), "depth"};
  }
  if (!(intrinsics.fx > 0.0 && intrinsics.fy > 0.0 && std::isfinite(intrinsics.cx) && std::isfinite(intrinsics.cy))) {
    return Error{"depth image: intrinsics need fx, fy > 0 and finite cx, cy", "intrinsics"};
  }
  if (!T_world_camera.matrix().allFinite()) return Error{"depth image: camera pose is not finite", "T_world_camera"};

  TsdfStorage& storage = *storage_;
  const double truncation = config_.truncation();
  const Eigen::Matrix3d R_world_camera = T_world_camera.rotation().matrix();
  const Eigen::Vector3d t_world_camera = T_world_camera.translation();

  // 1. Blocks within the truncation band of the readings of every stride-th pixel (samples
  //    along the ray closer than a block cover the band).
  const int samples = std::max(3, static_cast<int>(std::ceil(2.0 * truncation / storage.block_edge)) + 2);
  const int stride = config_.depth_allocation_stride;
  std::unordered_set<uint64_t> touched;
  for (int v = 0; v < depth.height; v += stride) {
    for (int u = 0; u < depth.width; u += stride) {
      const float z = depth.meters[static_cast<std::size_t>(v) * static_cast<std::size_t>(depth.width) + static_cast<std::size_t>(u)];
      if (!std::isfinite(z) || z <= 0.0f || !in_range(z, config_)) continue;
      const Eigen::Vector3d ray((u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, 1.0);
      for (int s = 0; s < samples; ++s) {
        const double along = z - truncation + 2.0 * truncation * s / (samples - 1);
        if (along <= 0.0) continue;
        const Eigen::Vector3d world = R_world_camera * (ray * along) + t_world_camera;
        touched.insert(storage.block_key(storage.block_of_point(world)));
      }
    }
  }
  // 2. Every voxel of those blocks projected into the image; camera coordinates of the voxel
  //    centres advance by one rotated voxel step per index.
  const Eigen::Matrix3d R_camera_world = R_world_camera.transpose();
  const Eigen::Matrix3d voxel_steps = R_camera_world * config_.voxel_size;
  const int size = storage.block_size;
  for (uint64_t key : touched) {
    TsdfStorage::Block& block = storage.find_or_create(key);
    const Eigen::Vector3i block_index = TsdfStorage::block_from_key(key);
    const Eigen::Vector3d first_centre = storage.voxel_centre(block_index, 0);
    const Eigen::Vector3d first_in_camera = R_camera_world * (first_centre - t_world_camera);
    int offset = 0;
    for (int z_index = 0; z_index < size; ++z_index) {
      for (int y_index = 0; y_index < size; ++y_index) {
        Eigen::Vector3d in_camera = first_in_camera + voxel_steps.col(2) * z_index + voxel_steps.col(1) * y_index;
        for (int x_index = 0; x_index < size; ++x_index, ++offset, in_camera += voxel_steps.col(0)) {
          if (in_camera.z() <= 0.0) continue;
          const double inverse_z = 1.0 / in_camera.z();
          const double u_exact = intrinsics.fx * in_camera.x() * inverse_z + intrinsics.cx + 0.5;
          const double v_exact = intrinsics.fy * in_camera.y() * inverse_z + intrinsics.cy + 0.5;
          if (u_exact < 0.0 || v_exact < 0.0 || u_exact >= depth.width || v_exact >= depth.height) continue;
          const float z = depth.meters[static_cast<std::size_t>(v_exact) * static_cast<std::size_t>(depth.width) + static_cast<std::size_t>(u_exact)];
          if (!std::isfinite(z) || z <= 0.0f || !in_range(z, config_)) continue;
          const double sdf = z - in_camera.z();
          if (sdf < -truncation) continue;
          storage.update(block, offset, static_cast<float>(std::min(sdf, truncation)));
        }
      }
    }
  }
  return ok_status();
}

Status TsdfVolume::integrate_scan(const Eigen::Vector3d& sensor_origin, std::span<const Eigen::Vector3d> end_points) {
  if (!sensor_origin.allFinite()) return Error{"scan: sensor origin is not finite", "sensor_origin"};
  for (std::size_t i = 0; i < end_points.size(); ++i) {
    if (!end_points[i].allFinite()) return Error{fmt::format("scan: end point {} is not finite", i), fmt::format("end_points[{}]", i)};
  }
  TsdfStorage& storage = *storage_;
  const double truncation = config_.truncation();
  const double step = config_.voxel_size / 2.0;
  for (const Eigen::Vector3d& end : end_points) {
    const Eigen::Vector3d ray = end - sensor_origin;
    const double range = ray.norm();
    if (!in_range(range, config_)) continue;
    const Eigen::Vector3d direction = ray / range;
    // Voxels along the ray through the band [range - truncation, range + truncation], each once.
    Eigen::Vector3i last(INT32_MIN, INT32_MIN, INT32_MIN);
    for (double along = std::max(0.0, range - truncation); along <= range + truncation; along += step) {
      const Eigen::Vector3i voxel = storage.voxel_of_point(sensor_origin + direction * along);
      if (voxel == last) continue;
      last = voxel;
      const Eigen::Vector3d centre = (voxel.cast<double>().array() + 0.5) * config_.voxel_size;
      const double sdf = range - (centre - sensor_origin).dot(direction);
      if (sdf < -truncation) continue;
      const auto [block, offset] = storage.locate_or_create(voxel);
      storage.update(*block, offset, static_cast<float>(std::min(sdf, truncation)));
    }
  }
  return ok_status();
}

std::pair<float, float> TsdfVolume::sample(const Eigen::Vector3d& point) const {
  return storage_->voxel(storage_->voxel_of_point(point));
}

msgs::MeshLayer TsdfVolume::extract_mesh() const { return marching_cubes(*storage_); }

msgs::TsdfLayer TsdfVolume::to_layer() const {
  msgs::TsdfLayer layer;
  layer.voxel_size = config_.voxel_size;
  layer.truncation_distance = config_.truncation();
  layer.block_size = static_cast<uint32_t>(config_.block_size);
  for (const uint64_t key : storage_->sorted_keys()) {
    const TsdfStorage::Block& block = *storage_->blocks.at(key);
    msgs::TsdfBlock out{TsdfStorage::block_from_key(key), {}, {}};
    out.distances.reserve(block.distances.size());
    for (int16_t stored : block.distances) out.distances.push_back(storage_->distance_of(stored));
    out.weights.assign(block.weights.begin(), block.weights.end());
    layer.blocks.push_back(std::move(out));
  }
  return layer;
}

Result<TsdfVolume> TsdfVolume::from_layer(const msgs::TsdfLayer& layer, TsdfConfig config) {
  HANZO_RETURN_IF_ERROR(validate_layer(layer));
  config.voxel_size = layer.voxel_size;
  config.truncation_distance = layer.truncation_distance;
  config.block_size = static_cast<int>(layer.block_size);
  HANZO_RETURN_IF_ERROR(config.validate());
  TsdfVolume volume(config);
  for (const msgs::TsdfBlock& in : layer.blocks) {
    if ((in.index.array().abs() >= (1 << 20)).any()) return Error{"tsdf layer: block index out of range", "tsdf.blocks.index"};
    const uint64_t key = TsdfStorage::block_key(in.index);
    if (volume.storage_->blocks.contains(key)) {
      return Error{fmt::format("tsdf layer: block ({}, {}, {}) appears twice", in.index.x(), in.index.y(), in.index.z()),
                   "tsdf.blocks.index"};
    }
    TsdfStorage::Block& block = volume.storage_->find_or_create(key);
    const float truncation = static_cast<float>(config.truncation());
    for (std::size_t i = 0; i < in.distances.size(); ++i) {
      block.distances[i] = volume.storage_->stored_distance(std::clamp(in.distances[i], -truncation, truncation));
      block.weights[i] = static_cast<uint16_t>(std::lround(std::min(in.weights[i], 65535.0f)));
    }
  }
  return volume;
}

std::size_t TsdfVolume::block_count() const { return storage_->blocks.size(); }

std::size_t TsdfVolume::memory_bytes() const {
  const std::size_t per_block = sizeof(TsdfStorage::Block) + (sizeof(int16_t) + sizeof(uint16_t)) * static_cast<std::size_t>(storage_->block_voxels) +
                                sizeof(uint64_t) + 3 * sizeof(void*);
  return storage_->blocks.size() * per_block + storage_->blocks.bucket_count() * sizeof(void*);
}

}  // namespace hanzo::fusion::maps
