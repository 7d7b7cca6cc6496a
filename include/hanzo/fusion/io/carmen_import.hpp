#pragma once
// CARMEN logs (the text format of the Radish 2D-laser data sets, optionally gzip-compressed):
//
//   FLASER n r_1 .. r_n x y theta odom_x odom_y odom_theta ipc_timestamp host logger_timestamp
//   ODOM x y theta tv rv accel ipc_timestamp host logger_timestamp
//
// FLASER scans become planar PointCloudMessages in the laser frame (beams evenly over 180 deg,
// first at -90 deg, right to left; readings at or beyond max_range are "no return" and left
// out). ODOM poses become differential-drive wheel odometry: between consecutive poses the
// centre moves the straight-line distance (negative when the motion is backwards) and turns
// by the heading change, so left += d - dtheta b / 2, right += d + dtheta b / 2. The scans' own
// poses (x y theta) are returned as a trajectory (for corrected logs: the reference).
// Times are the ipc_timestamp in seconds. An ODOM line at time 0 (the corrected logs add the
// corrected pose after every scan that way) re-anchors the odometry instead of being integrated.
// Imperfect times are detected per kind of line: when more than half of the scans' (or the
// odometry's) times do not increase (duplicates, as in a log printed with 6 significant digits:
// "1.13486e+09"), that kind's times are rebuilt from the other kind's
// (evenly between them in line order), or, when neither is usable, from the line order at
// nominal_scan_rate_hz; the report says so (timestamp_warning, also logged). After that, lines
// whose time does not increase are left out and counted.

#include <cstdint>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::io {

struct CarmenImportConfig {
  std::string laser_topic = "/laser";
  std::string odometry_topic = "/odom";
  double wheel_separation = 0.0;  ///< m, > 0 to import ODOM lines; 0 leaves them out
  double max_range = 80.0;        ///< m; readings at or beyond it are dropped (the logs use 81.83 / 81.91)
  double nominal_scan_rate_hz = 5.0;  ///< scan rate assumed when no line's time is usable
};

struct CarmenImportReport {
  uint64_t scans = 0;
  uint64_t odometry = 0;
  uint64_t skipped_lines = 0;       ///< NEFF, PARAM, unknown messages, time-0 ODOM re-anchors
  uint64_t rejected = 0;            ///< lines whose time does not increase
  std::string first_rejection;
  bool timestamps_reconstructed = false;
  std::string timestamp_warning;    ///< why and how the times were rebuilt ("" when they were used as written)
  Trajectory scan_poses;            ///< T_world_laser of every scan (z = 0)
};

/// A CARMEN log in memory: scans and odometry, each in time order.
struct CarmenLog {
  CarmenImportReport report;
  std::vector<msgs::PointCloudMessage> scans;          ///< planar, z = 0, frame "laser"
  std::vector<msgs::WheelOdometryMessage> odometry;    ///< only with config.wheel_separation > 0
};

/// Reads `path` (plain or .gz). A malformed line fails, naming file and line.
Result<CarmenLog> read_carmen(const std::string& path, const CarmenImportConfig& config);

/// Reads `path` (plain or .gz) and writes its scans (and odometry) to `writer` in time order.
/// A malformed line fails the import, naming file and line.
Result<CarmenImportReport> import_carmen(const std::string& path, SensorLogWriter& writer, const CarmenImportConfig& config);

}  // namespace hanzo::fusion::io
