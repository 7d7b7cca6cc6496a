#pragma once
// The peer libraries of bench_lidar, each behind a plain function so that PCL and Open3D
// headers stay in their own translation units. Every function takes the already downsampled
// clouds and includes in its time everything the library needs from there (kd-trees,
// normals or covariances, the registration itself).

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

}  // namespace bench
