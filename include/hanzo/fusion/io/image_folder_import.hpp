#pragma once
// Image folders as a camera log: the frames of a phone video, a drone's photos or a dataset's
// image folder (PNG, JPEG, BMP, TIFF, PGM/PPM through OpenCV's imgcodecs), one folder per camera.
//
//   - Order: the files of a folder sorted by name, digit runs compared as numbers ("frame9" before
//     "frame10"); other files (no image extension) are left out.
//   - Times, the first that applies:
//       1. times_path: one line per image, "TIME" (in the files' order: KITTI's times.txt) or
//          "TIME NAME" (TUM's rgb.txt: NAME a file of the first folder; its images take the
//          listed order). TIME in seconds; relative times (under 1e8 s: 1973) start at
//          time_origin.
//       2. file names that are times: a stem of 16 or more digits is nanoseconds (EuRoC:
//          1403715273262142976.png), a decimal number of seconds (TUM: 1305031102.175304.png).
//       3. rate_hz: frame i at time_origin + i / rate_hz.
//     None of them is an error that says so.
//   - Two folders are a stereo pair (left, right): the same number of images, paired by order; the
//     right camera's images take the left one's times.
// Images become mono8 (8-bit grey) or rgb8 (colour) messages on the topics, with the intrinsics
// when `camera` is given. Unreadable files, images of another size than the folder's first one,
// and times that do not increase are left out and counted (the first reason kept): one bad frame
// does not end an import. Calibration (with `camera`): the left camera at the body origin, the
// right one `baseline` metres along its x axis (a rectified pair).

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"

namespace hanzo::fusion::io {

struct ImageFolderImportConfig {
  std::vector<std::string> topics = {"/cam0", "/cam1"};  ///< per folder
  std::string times_path;    ///< times file (see above); empty: from the names or rate_hz
  double rate_hz = 0.0;      ///< frames per second when the times come from neither
  double time_origin = 1e9;  ///< Unix time (s) of relative times (default 2001-09-09T01:46:40Z)
  /// Intrinsics (and distortion) of the camera(s); width and height are taken from the images.
  std::optional<calib::CameraCalibration> camera;
  double baseline = 0.0;     ///< stereo: right camera along the left's x axis (metres)
};

struct ImageFolderImportReport {
  uint64_t images = 0;             ///< written, all folders
  uint64_t rejected = 0;           ///< files left out
  std::string first_rejection;
  std::string time_source;         ///< "times file", "file names" or "rate"
  bool relative_times = false;     ///< the times are relative ones placed at config.time_origin
  uint32_t width = 0, height = 0;  ///< of the images
  calib::Calibration calibration;  ///< the cameras (empty without config.camera)
};

/// `folders`: one (mono) or two (stereo: left, right). Errors (naming the folder or file): a
/// folder that is missing or holds no images, stereo folders of different counts or a missing
/// baseline, no way to time the images, a times file whose lines do not match the images.
Result<ImageFolderImportReport> import_image_folders(const std::vector<std::string>& folders, SensorLogWriter& writer,
                                                     const ImageFolderImportConfig& config);

}  // namespace hanzo::fusion::io
