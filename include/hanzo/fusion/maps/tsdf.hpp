#pragma once
// Truncated signed distance field (spec, "Map Representations / Signed Distance Field"): each
// voxel holds the signed distance (m) to the nearest observed surface, positive in front of it
// (the sensor's side), negative behind, truncated at +-truncation_distance, with a weight
// (how many observations averaged into it; the per-voxel uncertainty proxy of the FusionMap).
// Voxels live in sparse blocks (block_size^3 voxels) allocated only near observed surfaces, so
// memory follows the surface area, not the volume; a voxel takes 4 bytes (16-bit distance in
// steps of truncation / 32767, 16-bit weight).
//
// Integration (Curless & Levoy 1996, eq. 1-2: weighted running average, weights capped):
//  - depth images, projectively (KinectFusion, Newcombe et al. 2011, eq. 6-7, as Open3D's
//    ScalableTSDFVolume): a voxel takes sdf = depth(pixel) - z_camera(voxel), pinhole model
//    without distortion (undistort images first);
//  - range scans (LiDAR) along each ray: voxels within the truncation band around the return
//    take sdf = range - distance of the voxel centre along the ray.
// Voxel v covers [v, v + 1) * voxel_size; its value is sampled at its centre.
//
// Meshes come out by marching cubes (Lorensen & Cline 1987) over the zero crossing, between
// voxel centres whose weights are all > 0; vertices are shared between neighbouring cubes.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::maps {

struct TsdfConfig {
  /// Voxel edge (m); spec: typically 0.02-0.05.
  double voxel_size = 0.05;
  /// Truncation distance (m); 0: 3 x voxel_size, the spec's choice.
  double truncation_distance = 0.0;
  /// Voxels per block edge.
  int block_size = 8;
  /// Cap of the per-voxel weight (whole observations, 1 to 65535), so that a changed surface
  /// is relearned.
  float max_weight = 64.0f;
  /// Depth images: blocks are allocated from every n-th pixel in each direction (Open3D's
  /// depth_sampling_stride); voxels are then updated from every pixel.
  int depth_allocation_stride = 4;
  /// Depth readings and ranges outside [min_range, max_range] (m) are ignored; 0: no limit.
  double min_range = 0.0;
  double max_range = 0.0;

  double truncation() const { return truncation_distance > 0.0 ? truncation_distance : 3.0 * voxel_size; }
  /// Names the first invalid value.
  Status validate() const;
};

/// A depth image in meters, row-major (0 or non-finite: no reading).
struct DepthImageView {
  int width = 0;
  int height = 0;
  std::span<const float> meters;
};

struct TsdfStorage;  // the sparse blocks (src/maps/tsdf_storage.hpp)

class TsdfVolume {
 public:
  explicit TsdfVolume(const TsdfConfig& config);
  static Result<TsdfVolume> create(const TsdfConfig& config);
  ~TsdfVolume();
  TsdfVolume(TsdfVolume&&) noexcept;
  TsdfVolume& operator=(TsdfVolume&&) noexcept;

  /// Integrates a depth image seen from T_world_camera (camera: x right, y down, z forward).
  /// Fails, changing nothing, on a size mismatch, invalid intrinsics or a non-finite pose.
  Status integrate_depth(const DepthImageView& depth, const msgs::CameraIntrinsics& intrinsics, const SE3& T_world_camera);
  /// Integrates returns (world frame) seen from sensor_origin (world). Fails, changing
  /// nothing, on non-finite input.
  Status integrate_scan(const Eigen::Vector3d& sensor_origin, std::span<const Eigen::Vector3d> end_points);

  /// Signed distance (m) and weight of the voxel holding `point`; weight 0 when unobserved.
  std::pair<float, float> sample(const Eigen::Vector3d& point) const;

  /// Marching-cubes mesh of the zero crossing (world frame).
  msgs::MeshLayer extract_mesh() const;

  /// The volume as a FusionMap layer, and back (the layer must pass the FusionMap checks).
  msgs::TsdfLayer to_layer() const;
  static Result<TsdfVolume> from_layer(const msgs::TsdfLayer& layer, TsdfConfig config = {});

  std::size_t block_count() const;
  /// Bytes held by the blocks and their index.
  std::size_t memory_bytes() const;
  const TsdfConfig& config() const { return config_; }

 private:
  TsdfConfig config_;
  std::unique_ptr<TsdfStorage> storage_;
};

}  // namespace hanzo::fusion::maps
