#pragma once
// KITTI odometry sequences (http://www.cvlibs.net/datasets/kitti/eval_odometry.php):
//
//   SEQUENCE/times.txt            one time per frame, seconds since the start of the sequence
//   SEQUENCE/calib.txt            "P0: 12 numbers" .. "P3:", "Tr: 12 numbers" (velodyne -> cam0)
//   SEQUENCE/velodyne/NNNNNN.bin  float32 x y z reflectance per point (metres, reflectance 0..1)
//   SEQUENCE/image_0|image_1/NNNNNN.png   rectified left / right grayscale (optional)
//   poses/SS.txt                  (sequences 00-10) 12 numbers a line: T_cam0start_cam0 row-major 3x4
//
// Frames become messages on the LiDAR topic (PointCloudMessage, intensity = reflectance) and,
// when the image folders exist, on the two camera topics (mono8, intrinsics from P0 / P1, no
// distortion: the images are rectified). Time of frame i = time_origin + times[i]: the
// odometry benchmark has no absolute time, and the sensor log wants Unix time. A sequence that
// `hanzo-fusion export dataset` wrote also has SEQUENCE/timestamps_ns.txt (each frame's Unix time,
// integer ns): those are taken instead (they must be as many as times.txt's).
//
// The body frame is the Velodyne (x forward, y left, z up: FLU). The calibration returned
// holds lidar_to_body (identity), cam0_to_body = Tr^-1, cam1_to_body = Tr^-1 T_cam0_cam1 (the
// baseline from P1). Ground truth, when the poses file exists, is returned in the body frame:
// T_lidar0_lidari = Tr^-1 T_cam0start_cam0i Tr, one pose per frame at the frame's time.
//
// Errors (name the file): missing times.txt or calib.txt, a frame count that differs between
// times.txt, velodyne/, the image folders and the poses file, a .bin whose size is not a
// multiple of 16 bytes, non-finite points, times that do not increase.

#include <cstdint>
#include <string>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::io {

struct KittiImportConfig {
  std::string lidar_topic = "/lidar";
  std::string left_camera_topic = "/cam0";   ///< image_0
  std::string right_camera_topic = "/cam1";  ///< image_1
  bool import_images = true;                 ///< false: point clouds only
  /// Poses file; empty: SEQUENCE/../../poses/<sequence name>.txt when it exists.
  std::string poses_path;
  /// Unix time of times.txt's zero, seconds (default 2001-09-09T01:46:40Z, a round synthetic epoch).
  double time_origin = 1e9;
};

struct KittiImportReport {
  uint64_t frames = 0;
  uint64_t scans = 0;
  uint64_t images = 0;
  uint64_t points = 0;
  std::string poses_path;           ///< the poses file used, empty when none
  bool absolute_times = false;      ///< the times came from timestamps_ns.txt (absolute), not times.txt + time_origin
  Trajectory ground_truth;          ///< T_lidar0_lidar per frame; empty without a poses file
  calib::Calibration calibration;   ///< lidar, cam0, cam1 to body (= lidar)
};

Result<KittiImportReport> import_kitti(const std::string& sequence_dir, SensorLogWriter& writer, const KittiImportConfig& config);

}  // namespace hanzo::fusion::io
