#pragma once
// Plain CSV sensor files: the columns `log export --format csv` writes (csv_export.hpp) for
// IMU, GNSS and wheel odometry, read back. The header line says which sensor a file holds:
//
//   timestamp_ns,ax,ay,az,wx,wy,wz                                    -> IMU
//   timestamp_ns,latitude,longitude,altitude,fix_type[,satellites_used,hdop] -> GNSS
//   timestamp_ns,left_distance,right_distance,wheel_separation        -> wheel odometry
//
// Times are integer nanoseconds since the Unix epoch; fix_type is NO_FIX, FIX_2D, FIX_3D,
// RTK_FLOAT or RTK_FIXED. Lines starting with '#' and empty lines are skipped. Every message
// is validated; an invalid line fails the whole file, naming file, line and field.

#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::io {

/// Reads one CSV sensor file. Timestamps must increase strictly (a repeated or earlier time is
/// an error naming both lines).
Result<std::vector<msgs::SensorMessage>> read_sensor_csv(const std::string& path);
Result<std::vector<msgs::SensorMessage>> parse_sensor_csv(const std::string& text, const std::string& source_name);

}  // namespace hanzo::fusion::io
