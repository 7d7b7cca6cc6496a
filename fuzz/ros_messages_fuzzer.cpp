// Fuzz target: the ROS message decoders of `import rosbag` / `import ros2bag`
// (io/ros_conversion.hpp), which read whatever a bag holds. The first byte picks the message
// type, the second the wire format (ROS 1 or CDR); the rest is the message. Any input must be
// decoded or refused with an error, never read out of bounds or crash.

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "hanzo/fusion/io/ros_conversion.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace hanzo::fusion::io::ros;
  if (size < 2) return 0;
  const Serialization serialization = data[1] % 2 == 0 ? Serialization::kRos1 : Serialization::kCdr;
  const std::string_view message(reinterpret_cast<const char*>(data) + 2, size - 2);
  switch (data[0] % 10) {
    case 0: (void)imu_from_ros(message, serialization); break;
    case 1: (void)gnss_from_ros(message, serialization); break;
    case 2: (void)point_cloud_from_ros(message, serialization); break;
    case 3: (void)image_from_ros(message, serialization); break;
    case 4: (void)compressed_image_from_ros(message, serialization); break;
    case 5: (void)camera_info_from_ros(message, serialization); break;
    case 6: (void)transforms_from_ros(message, serialization); break;
    case 7: (void)odometry_twist_from_ros(message, serialization); break;
    case 8: (void)twist_stamped_from_ros(message, serialization); break;
    default: (void)imu_from_ros(message, serialization); break;
  }
  return 0;
}
