#pragma once
// Conversions between cloud::PointCloud and pcl::PointCloud<PointT>, for code that mixes
// hanzo-fusion with PCL algorithms. Header-only and opt-in: including it requires PCL's headers
// (hanzo-fusion's other headers never include PCL). Positions always convert; intensity, ring,
// time and normals convert when PointT has the matching PCL field (intensity; ring; time;
// normal_x/y/z), detected with PCL's field traits.

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "hanzo/fusion/cloud/point_cloud.hpp"

namespace hanzo::fusion::cloud {

namespace pcl_detail {
template <typename PointT, typename Tag>
constexpr bool has_field = pcl::traits::has_field<PointT, Tag>::value;
}  // namespace pcl_detail

/// `cloud` as a dense, unorganized PCL cloud.
template <typename PointT>
pcl::PointCloud<PointT> to_pcl(const PointCloud& cloud) {
  pcl::PointCloud<PointT> out;
  out.resize(cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) {
    PointT& point = out[i];
    point.x = cloud.positions[i].x();
    point.y = cloud.positions[i].y();
    point.z = cloud.positions[i].z();
    if constexpr (pcl_detail::has_field<PointT, pcl::fields::intensity>) {
      if (cloud.has_intensities()) point.intensity = cloud.intensities[i];
    }
    if constexpr (pcl_detail::has_field<PointT, pcl::fields::normal_x>) {
      if (cloud.has_normals()) {
        point.normal_x = cloud.normals[i].x();
        point.normal_y = cloud.normals[i].y();
        point.normal_z = cloud.normals[i].z();
      }
    }
  }
  out.width = static_cast<uint32_t>(cloud.size());
  out.height = 1;
  out.is_dense = true;
  return out;
}

/// A PCL cloud as a PointCloud; non-finite points (organized clouds' missing returns) are dropped.
template <typename PointT>
PointCloud from_pcl(const pcl::PointCloud<PointT>& input) {
  PointCloud cloud;
  cloud.positions.reserve(input.size());
  for (const PointT& point : input) {
    const Eigen::Vector3f position(point.x, point.y, point.z);
    if (!position.allFinite()) continue;
    cloud.positions.push_back(position);
    if constexpr (pcl_detail::has_field<PointT, pcl::fields::intensity>) cloud.intensities.push_back(point.intensity);
    if constexpr (pcl_detail::has_field<PointT, pcl::fields::normal_x>) {
      cloud.normals.emplace_back(point.normal_x, point.normal_y, point.normal_z);
    }
  }
  return cloud;
}

}  // namespace hanzo::fusion::cloud
