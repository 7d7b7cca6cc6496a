#include <pcl/features/normal_3d.h>
#include <pcl/registration/gicp.h>
#include <pcl/registration/icp.h>
#include <pcl/registration/ndt.h>

#include "hanzo/fusion/cloud/pcl_conversion.hpp"
#include "lidar_peers.hpp"

namespace bench {

using hanzo::fusion::SE3;

namespace {

template <typename Registration, typename PointT>
PeerResult run(Registration& registration, const typename pcl::PointCloud<PointT>::Ptr& source,
               const typename pcl::PointCloud<PointT>::Ptr& target) {
  registration.setInputSource(source);
  registration.setInputTarget(target);
  pcl::PointCloud<PointT> aligned;
  registration.align(aligned);
  PeerResult result;
  result.T_target_source = SE3::from_matrix(registration.getFinalTransformation().template cast<double>());
  result.converged = registration.hasConverged();
  return result;
}

pcl::PointCloud<pcl::PointNormal>::Ptr with_normals(const hanzo::fusion::cloud::PointCloud& cloud) {
  auto points = std::make_shared<pcl::PointCloud<pcl::PointNormal>>(hanzo::fusion::cloud::to_pcl<pcl::PointNormal>(cloud));
  pcl::NormalEstimation<pcl::PointNormal, pcl::PointNormal> estimation;
  estimation.setInputCloud(points);
  estimation.setKSearch(10);
  estimation.compute(*points);
  return points;
}

}  // namespace

PeerResult pcl_register(PeerMethod method, const hanzo::fusion::cloud::PointCloud& source,
                        const hanzo::fusion::cloud::PointCloud& target, double max_correspondence_distance,
                        double ndt_resolution) {
  using Cloud = pcl::PointCloud<pcl::PointXYZ>;
  if (method == PeerMethod::kIcpPlane) {
    pcl::IterativeClosestPointWithNormals<pcl::PointNormal, pcl::PointNormal> icp;
    icp.setMaxCorrespondenceDistance(max_correspondence_distance);
    icp.setMaximumIterations(64);
    icp.setTransformationEpsilon(1e-8);
    return run<decltype(icp), pcl::PointNormal>(icp, with_normals(source), with_normals(target));
  }
  const auto source_points = std::make_shared<Cloud>(hanzo::fusion::cloud::to_pcl<pcl::PointXYZ>(source));
  const auto target_points = std::make_shared<Cloud>(hanzo::fusion::cloud::to_pcl<pcl::PointXYZ>(target));
  switch (method) {
    case PeerMethod::kIcp: {
      pcl::IterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> icp;
      icp.setMaxCorrespondenceDistance(max_correspondence_distance);
      icp.setMaximumIterations(64);
      icp.setTransformationEpsilon(1e-8);
      return run<decltype(icp), pcl::PointXYZ>(icp, source_points, target_points);
    }
    case PeerMethod::kGicp: {
      pcl::GeneralizedIterativeClosestPoint<pcl::PointXYZ, pcl::PointXYZ> gicp;
      gicp.setMaxCorrespondenceDistance(max_correspondence_distance);
      gicp.setMaximumIterations(64);
      gicp.setCorrespondenceRandomness(10);  // neighbours per covariance, as ours
      return run<decltype(gicp), pcl::PointXYZ>(gicp, source_points, target_points);
    }
    case PeerMethod::kNdt: {
      pcl::NormalDistributionsTransform<pcl::PointXYZ, pcl::PointXYZ> ndt;
      ndt.setResolution(static_cast<float>(ndt_resolution));
      ndt.setStepSize(0.1);
      ndt.setTransformationEpsilon(0.01);
      ndt.setMaximumIterations(64);
      return run<decltype(ndt), pcl::PointXYZ>(ndt, source_points, target_points);
    }
    default: return {};
  }
}

}  // namespace bench
