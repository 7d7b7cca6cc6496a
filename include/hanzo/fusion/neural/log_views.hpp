#pragma once
// Posed images for neural reconstruction from a session: a sensor log's camera images at the
// poses of a trajectory (the session's optimized one, or any other in TUM format), through the
// calibration's camera.
//
// Each image of the camera's topic (the image time shifted by the camera's time_offset into body
// time) gets T_world_camera = T_world_body(t) T_body_camera, T_world_body interpolated between
// the trajectory's two poses around t (images outside the trajectory's span, or further than
// max_gap from both neighbours, are left out and counted). A view is kept when the camera moved
// min_translation or turned min_rotation_degrees since the last kept view (the first always),
// at most max_views (evenly thinned when there are more). Intrinsics and distortion come from
// the calibration's camera, else from the image message; radtan images are undistorted to the
// pinhole camera with the same focal lengths, equidistant (fisheye) ones too. Colour images
// keep their colour, mono8 images are grey in all three channels.
//
// Failures (each an Error naming the file and what is wrong): an unreadable log, trajectory or
// calibration, no camera in the calibration (or not the named one), no image on the topic, no
// image inside the trajectory, intrinsics nowhere, an image whose size differs from the
// calibration's.

#include <cstddef>
#include <string>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/neural/view_dataset.hpp"

namespace hanzo::fusion::neural {

struct LogViewsConfig {
  std::string camera = "";        ///< the calibration's sensor ("" : its first camera)
  std::string topic = "";         ///< image topic ("": /sensors/<camera>, else the log's only image topic)
  double min_translation = 0.10;  ///< metres moved since the last kept view
  double min_rotation_degrees = 5.0;
  double max_gap = 0.5;           ///< seconds to the nearest trajectory pose at most
  int max_views = 300;
  int downscale = 1;
};

struct LogViews {
  ViewDataset dataset;
  std::size_t images = 0;            ///< on the topic
  std::size_t outside_trajectory = 0;  ///< left out: no pose near enough
  std::string topic;
};

Result<LogViews> load_log_views(const std::string& log_path, const std::string& trajectory_path, const std::string& calibration_path,
                                const LogViewsConfig& config = {});

}  // namespace hanzo::fusion::neural
