#include <cstring>

#include <open3d/camera/PinholeCameraIntrinsic.h>
#include <open3d/geometry/Image.h>
#include <open3d/geometry/RGBDImage.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/pipelines/integration/ScalableTSDFVolume.h>

#include "maps_peers.hpp"

namespace hanzo::fusion::bench {

struct Open3dTsdf::State {
  open3d::pipelines::integration::ScalableTSDFVolume volume;
  open3d::camera::PinholeCameraIntrinsic intrinsic;
  open3d::geometry::Image color;
  int width;
  int height;
};

Open3dTsdf::Open3dTsdf(double voxel, double truncation, int width, int height, double fx, double fy, double cx, double cy)
    : state_(new State{{voxel, truncation, open3d::pipelines::integration::TSDFVolumeColorType::NoColor},
                       {width, height, fx, fy, cx, cy},
                       {},
                       width,
                       height}) {
  state_->color.Prepare(width, height, 3, 1);
}

Open3dTsdf::~Open3dTsdf() = default;

void Open3dTsdf::integrate(const std::vector<uint16_t>& depth_mm, const Eigen::Matrix4d& T_camera_world) {
  open3d::geometry::Image depth;
  depth.Prepare(state_->width, state_->height, 1, 2);
  std::memcpy(depth.data_.data(), depth_mm.data(), depth_mm.size() * sizeof(uint16_t));
  const auto rgbd = open3d::geometry::RGBDImage::CreateFromColorAndDepth(state_->color, depth, 1000.0, 100.0, false);
  state_->volume.Integrate(*rgbd, state_->intrinsic, T_camera_world);
}

Open3dMeshSize Open3dTsdf::extract_mesh() {
  const auto mesh = state_->volume.ExtractTriangleMesh();
  return {mesh->vertices_.size(), mesh->triangles_.size()};
}

}  // namespace hanzo::fusion::bench
