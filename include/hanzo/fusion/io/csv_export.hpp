#pragma once
// CSV rows for decoded log messages (`hanzo-fusion log export --format csv`). One header per
// message type; numbers in shortest round-trip form; times in integer nanoseconds.
//
//   imu:            timestamp_ns,ax,ay,az,wx,wy,wz                         (m/s^2, rad/s, IMU frame)
//   gnss:           timestamp_ns,latitude,longitude,altitude,fix_type,satellites_used,hdop
//   wheel_odometry: timestamp_ns,left_distance,right_distance,wheel_separation   (m, cumulative)
//   radar:          timestamp_ns,target,range,azimuth,elevation,radial_velocity,rcs (one row per target)
//   point_cloud:    timestamp_ns,points,has_intensity,has_ring,has_point_time   (one row per scan)
//   image:          timestamp_ns,width,height,encoding                            (one row per image)
//   pose_estimate:  timestamp_ns,x,y,z,qw,qx,qy,qz,vx,vy,vz                      (world ENU)

#include <string>

#include "hanzo/fusion/io/sensor_log.hpp"

namespace hanzo::fusion::io {

/// The header line (with '\n') for the type of `entry`.
std::string csv_header(const LogEntry& entry);
/// Appends the row(s) of `entry` (each ending in '\n').
void append_csv_rows(const LogEntry& entry, std::string& out);

}  // namespace hanzo::fusion::io
