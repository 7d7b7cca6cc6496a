#pragma once
// Open3D's ScalableTSDFVolume behind a small interface, so that Open3D's headers stay out of
// bench_maps.cpp (compiled with relaxed warnings in maps_peers_open3d.cpp).

#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

namespace hanzo::fusion::bench {

struct Open3dMeshSize {
  std::size_t vertices = 0;
  std::size_t triangles = 0;
};

class Open3dTsdf {
 public:
  /// Depth images are uint16 millimetres (Open3D's usual input), width x height, pinhole.
  Open3dTsdf(double voxel, double truncation, int width, int height, double fx, double fy, double cx, double cy);
  ~Open3dTsdf();
  /// T_camera_world (Open3D's "extrinsic").
  void integrate(const std::vector<uint16_t>& depth_mm, const Eigen::Matrix4d& T_camera_world);
  Open3dMeshSize extract_mesh();

 private:
  struct State;
  std::unique_ptr<State> state_;
};

}  // namespace hanzo::fusion::bench
