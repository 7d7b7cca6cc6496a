#pragma once
// The peer libraries of bench_lidar, each behind a plain function so that PCL and Open3D
// headers stay in their own translation units. Every function takes the already downsampled
// clouds and includes in its time everything the library needs from there (kd-trees,
// normals or covariances, the registration itself).

#include <memory>
#include <string>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/core/se3.hpp"

namespace bench {

struct PeerResult {
  hanzo::fusion::SE3 T_target_source;
  int iterations = 0;
  bool converged = false;
};

enum class PeerMethod { kIcp, kIcpPlane, kGicp, kNdt };

/// PCL 1.13: IterativeClosestPoint, IterativeClosestPointWithNormals, GeneralizedIterativeClosestPoint,
/// NormalDistributionsTransform.
PeerResult pcl_register(PeerMethod method, const hanzo::fusion::cloud::PointCloud& source,
                        const hanzo::fusion::cloud::PointCloud& target, double max_correspondence_distance,
                        double ndt_resolution);
/// Open3D 0.16: RegistrationICP, point-to-point and point-to-plane (target normals from 10 neighbours).
PeerResult open3d_register(PeerMethod method, const hanzo::fusion::cloud::PointCloud& source,
                           const hanzo::fusion::cloud::PointCloud& target, double max_correspondence_distance);

/// Open3D 0.16 global registration, the usual pipeline of its tutorial: FPFH features (radius
/// 5 x voxel, normals from 2 x voxel), RANSAC on feature matches (mutual filter, edge-length
/// 0.9 and distance 1.5 x voxel checkers, at most 100000 iterations, confidence 0.999), then
/// point-to-plane ICP (correspondences within min(1 m, 2 x voxel)). The target (the map) and
/// its features are prepared once by open3d_prepare_global.
struct Open3dGlobalTarget;
std::shared_ptr<Open3dGlobalTarget> open3d_prepare_global(const hanzo::fusion::cloud::PointCloud& target, double voxel);
PeerResult open3d_global_register(const hanzo::fusion::cloud::PointCloud& source, const Open3dGlobalTarget& target, double voxel);

}  // namespace bench
