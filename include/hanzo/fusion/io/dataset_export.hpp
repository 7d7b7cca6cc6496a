#pragma once
// Training-data export: a sensor log's LiDAR sweeps and camera images, synchronized into
// frames, with the poses of an (optimized) trajectory as labels and the calibration, in the
// layouts perception tooling reads.
//
// Frames: one per message of the reference sensor (the first LiDAR, else the first camera;
// every `every`-th one). Each other sensor contributes its message nearest in time, when it is
// within max_time_difference_s; a frame missing one of them is left out and counted (KITTI
// needs every sensor in every frame; nuScenes-like output keeps the frame with what it has when
// require_all_sensors is false). Sensor times map to the body clock by the calibration's
// time_offset (t_body = t_sensor + offset), and a sensor's pose is
// T_world_sensor(t) = T_world_body(t) * T_body_sensor, T_world_body interpolated on SE3 between
// the two trajectory poses around t; a frame whose time is outside the trajectory, or between
// poses more than max_trajectory_gap_s apart, is left out and counted.
// Sweeps with per-point times are deskewed with the trajectory (each point moved into the
// sensor frame at the message's time) unless deskew is false. Images with distortion are
// undistorted onto the same intrinsics (pinhole, no distortion), as both layouts assume.
//
// KITTI odometry layout (out/):
//   sequences/00/velodyne/000000.bin  float32 x, y, z, reflectance (0..1) per point, LiDAR frame
//   sequences/00/image_<i>/000000.png camera i (configuration order): mono8 / depth16 as 1 channel, colour as 3
//   sequences/00/calib.txt            P<i>: K_i [R|t] of camera i from camera 0 (3x4); Tr: T_camera0_lidar (3x4)
//   sequences/00/times.txt            seconds since the first frame, one line per frame
//   sequences/00/timestamps_ns.txt    the frames' absolute times (ns since the epoch; not in KITTI)
//   poses/00.txt                      T_camera0(first)^-1 T_camera0(i), row-major 3x4 per frame
// "camera 0" is the first camera, or the LiDAR when there is none (then Tr is the identity).
//
// nuScenes-like layout (out/): the devkit's tables as JSON in v1.0-hanzo/ (scene, sample,
// sample_data, ego_pose, calibrated_sensor, sensor, log; the annotation tables empty), files in
// samples/<CHANNEL>/ (channel: the sensor name upper-cased), LiDAR sweeps as .pcd.bin (float32
// x, y, z, intensity 0..255, ring), images as .jpg (colour, mono) or .png (depth); ego poses of
// the body at each file's time; tokens are deterministic (32 hex digits from sensor and time),
// so exporting twice gives identical files.

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::io {

enum class DatasetLayout { kKittiOdometry, kNuscenes };
/// "kitti", "nuscenes".
Result<DatasetLayout> dataset_layout_from_name(const std::string& name);

/// A LiDAR or camera of the log: its name in the calibration and the topic it was logged on.
struct DatasetSensor {
  std::string name;
  std::string topic;
  bool is_camera = false;
};

struct DatasetExportConfig {
  DatasetLayout layout = DatasetLayout::kKittiOdometry;
  std::vector<DatasetSensor> sensors;  ///< LiDARs and cameras, in output order
  std::string reference_sensor;        ///< "" : the first LiDAR of `sensors`, else the first camera
  int every = 1;                       ///< export every N-th reference message (>= 1)
  double max_time_difference_s = 0.05;  ///< another sensor's nearest message must be this close (s)
  double max_trajectory_gap_s = 0.5;    ///< trajectory poses around a time at most this far apart (s)
  bool deskew = true;                   ///< sweeps with per-point times moved to their message time
  bool require_all_sensors = true;      ///< nuScenes-like only: false keeps frames missing a sensor
  int jpeg_quality = 95;                ///< nuScenes-like images, 1..100
  std::string scene_name = "scene-0001";  ///< nuScenes-like scene and log names
};

struct DatasetExportSummary {
  uint64_t frames = 0;                         ///< frames written
  uint64_t reference_messages = 0;             ///< messages of the reference sensor in the log
  uint64_t outside_trajectory = 0;             ///< frames left out: no pose for their time
  uint64_t missing_sensor = 0;                 ///< frames left out: a sensor had no message close enough
  uint64_t deskewed_sweeps = 0;
  uint64_t undistorted_images = 0;
  std::map<std::string, uint64_t> files_by_sensor;
  uint64_t bytes_written = 0;
  double first_frame_time_s = 0.0;
  double last_frame_time_s = 0.0;
};

/// Writes the dataset into `out_dir`, which must not exist (or be empty). Fails before writing
/// anything when a sensor has no calibration entry (or a camera no intrinsics), the reference
/// sensor is unknown, the log has no message of the reference sensor, or no frame has a pose;
/// a failure while writing removes what was written. `trajectory` holds T_world_body.
Result<DatasetExportSummary> export_dataset(const std::string& log_path, const Trajectory& trajectory,
                                            const calib::Calibration& calibration, const std::string& out_dir,
                                            const DatasetExportConfig& config);

}  // namespace hanzo::fusion::io
