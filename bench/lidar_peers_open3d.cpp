#include <open3d/geometry/KDTreeSearchParam.h>
#include <open3d/geometry/PointCloud.h>
#include <open3d/pipelines/registration/Registration.h>
#include <open3d/pipelines/registration/TransformationEstimation.h>

#include "lidar_peers.hpp"

namespace bench {

namespace {

open3d::geometry::PointCloud to_open3d(const hanzo::fusion::cloud::PointCloud& cloud) {
  open3d::geometry::PointCloud out;
  out.points_.reserve(cloud.size());
  for (const auto& p : cloud.positions) out.points_.push_back(p.cast<double>());
  return out;
}

}  // namespace

PeerResult open3d_register(PeerMethod method, const hanzo::fusion::cloud::PointCloud& source,
                           const hanzo::fusion::cloud::PointCloud& target, double max_correspondence_distance) {
  namespace registration = open3d::pipelines::registration;
  open3d::geometry::PointCloud source_points = to_open3d(source);
  open3d::geometry::PointCloud target_points = to_open3d(target);
  const registration::ICPConvergenceCriteria criteria(1e-6, 1e-6, 64);
  registration::RegistrationResult result;
  const open3d::geometry::KDTreeSearchParamKNN neighbours(10);
  switch (method) {
    case PeerMethod::kIcp:
      result = registration::RegistrationICP(source_points, target_points, max_correspondence_distance,
                                             Eigen::Matrix4d::Identity(), registration::TransformationEstimationPointToPoint(),
                                             criteria);
      break;
    case PeerMethod::kIcpPlane:
      target_points.EstimateNormals(neighbours);
      result = registration::RegistrationICP(source_points, target_points, max_correspondence_distance,
                                             Eigen::Matrix4d::Identity(), registration::TransformationEstimationPointToPlane(),
                                             criteria);
      break;
    default: return {};
  }
  PeerResult out;
  out.T_target_source = hanzo::fusion::SE3::from_matrix(result.transformation_);
  out.converged = result.fitness_ > 0.0;
  return out;
}

}  // namespace bench
