#pragma once
// The peer of bench_io's ROS 2 PointCloud2 decoding, behind a plain function so that PCL's
// headers stay in their own translation unit.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace bench {

struct Cloud2Field {
  std::string name;
  uint32_t offset;
  uint8_t datatype;  // sensor_msgs/PointField
};

/// PCL 1.13: a pcl::PCLPointCloud2 of these fields and bytes (what pcl_conversions makes of a
/// sensor_msgs/PointCloud2) into a pcl::PointCloud<pcl::PointXYZI> with pcl::fromPCLPointCloud2.
/// Returns the number of points.
std::size_t pcl_points_from_cloud2(const std::vector<Cloud2Field>& fields, uint32_t point_step, uint32_t width,
                                   const std::vector<uint8_t>& data);

}  // namespace bench
