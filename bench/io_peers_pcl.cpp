#include <pcl/PCLPointCloud2.h>
#include <pcl/conversions.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "io_peers.hpp"

namespace bench {

std::size_t pcl_points_from_cloud2(const std::vector<Cloud2Field>& fields, uint32_t point_step, uint32_t width,
                                   const std::vector<uint8_t>& data) {
  pcl::PCLPointCloud2 message;
  message.height = 1;
  message.width = width;
  message.point_step = point_step;
  message.row_step = point_step * width;
  message.is_dense = true;
  for (const Cloud2Field& f : fields) {
    pcl::PCLPointField field;
    field.name = f.name;
    field.offset = f.offset;
    field.datatype = f.datatype;
    field.count = 1;
    message.fields.push_back(field);
  }
  message.data = data;
  pcl::PointCloud<pcl::PointXYZI> cloud;
  pcl::fromPCLPointCloud2(message, cloud);
  return cloud.size();
}

}  // namespace bench
