#pragma once
// TUM RGB-D sequences (https://cvg.cit.tum.de/data/datasets/rgbd-dataset/file_formats):
//
//   DIR/rgb.txt          '#' comments, then "timestamp filename" (rgb/<t>.png, 640x480 colour)
//   DIR/depth.txt        the same for depth/<t>.png (16-bit, 5000 per metre, 0 = no measurement)
//   DIR/groundtruth.txt  TUM trajectory of the colour camera's optical centre
//
// Colour images become rgb8 messages on rgb_topic, depth images depth16 messages in
// millimetres on depth_topic (TUM's 0.2 mm steps rounded to 1 mm). The folder name tells the
// Kinect: "freiburg1" / "freiburg2" / "freiburg3" select the intrinsics and distortion TUM
// published for it (fr3 images are already undistorted); another name leaves the intrinsics
// out unless CameraIntrinsics are given in the config. accelerometer.txt (the Kinect's tilt
// sensor, no gyroscope) is not imported: it is not an IMU.
// Calibration: both cameras at the body origin (body = colour camera; the depth images are
// registered to it). A row whose time does not increase is left out and counted. Depth images
// take the time of the colour image they pair with (max_depth_offset).

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"

namespace hanzo::fusion::io {

struct TumRgbdImportConfig {
  std::string rgb_topic = "/rgb";
  std::string depth_topic = "/depth";
  bool import_depth = true;
  /// Seconds: each depth image is paired with the colour image nearest in time within this
  /// (each colour image with at most one, the nearest: TUM's associate.py) and stamped with its
  /// time, as an RGB-D odometry pairs them; depth images without a colour image that near are
  /// left out and counted. 0 keeps the depth images' own times.
  double max_depth_offset = 0.02;
  /// Overrides the intrinsics chosen from the folder name.
  std::optional<calib::CameraCalibration> camera;
};

struct TumRgbdImportReport {
  uint64_t rgb_images = 0;
  uint64_t depth_images = 0;
  uint64_t rejected = 0;  ///< rows whose time did not increase
  uint64_t depth_unpaired = 0;  ///< depth images without a colour image within max_depth_offset
  std::string first_rejection;
  std::string camera_model;        ///< "freiburg1" / "freiburg2" / "freiburg3" / "config" / "" (none)
  Trajectory ground_truth;         ///< empty without groundtruth.txt
  calib::Calibration calibration;  ///< rgb (and depth) to body
};

Result<TumRgbdImportReport> import_tum_rgbd(const std::string& dir, SensorLogWriter& writer, const TumRgbdImportConfig& config);

}  // namespace hanzo::fusion::io
