#include <open3d/geometry/KDTreeSearchParam.h>
#include <open3d/geometry/PointCloud.h>
#include <open3d/pipelines/registration/CorrespondenceChecker.h>
#include <open3d/pipelines/registration/Feature.h>
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

struct Open3dGlobalTarget {
  open3d::geometry::PointCloud points;
  std::shared_ptr<open3d::pipelines::registration::Feature> features;
};

namespace {

// Normals and FPFH features of a downsampled cloud.
std::shared_ptr<open3d::pipelines::registration::Feature> fpfh(open3d::geometry::PointCloud& points, double voxel) {
  points.EstimateNormals(open3d::geometry::KDTreeSearchParamHybrid(2.0 * voxel, 30));
  return open3d::pipelines::registration::ComputeFPFHFeature(points, open3d::geometry::KDTreeSearchParamHybrid(5.0 * voxel, 100));
}

}  // namespace

std::shared_ptr<Open3dGlobalTarget> open3d_prepare_global(const hanzo::fusion::cloud::PointCloud& target, double voxel) {
  auto prepared = std::make_shared<Open3dGlobalTarget>();
  prepared->points = to_open3d(target);
  prepared->features = fpfh(prepared->points, voxel);
  return prepared;
}

PeerResult open3d_global_register(const hanzo::fusion::cloud::PointCloud& source, const Open3dGlobalTarget& target, double voxel) {
  namespace registration = open3d::pipelines::registration;
  open3d::geometry::PointCloud source_points = to_open3d(source);
  const auto source_features = fpfh(source_points, voxel);
  const registration::CorrespondenceCheckerBasedOnEdgeLength edge_length(0.9);
  const registration::CorrespondenceCheckerBasedOnDistance distance(1.5 * voxel);
  const registration::RegistrationResult coarse = registration::RegistrationRANSACBasedOnFeatureMatching(
      source_points, target.points, *source_features, *target.features, true, 1.5 * voxel,
      registration::TransformationEstimationPointToPoint(false), 3, {edge_length, distance}, registration::RANSACConvergenceCriteria(100000, 0.999));
  const registration::RegistrationResult fine =
      registration::RegistrationICP(source_points, target.points, std::min(1.0, 2.0 * voxel), coarse.transformation_,
                                    registration::TransformationEstimationPointToPlane(), registration::ICPConvergenceCriteria(1e-6, 1e-6, 64));
  PeerResult out;
  out.T_target_source = hanzo::fusion::SE3::from_matrix(fine.transformation_);
  out.converged = fine.fitness_ > 0.0;
  return out;
}

}  // namespace bench
