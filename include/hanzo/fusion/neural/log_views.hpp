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
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
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

/// One camera image as a view at T_world_camera (OpenCV optical frame): undistorted to the
/// pinhole camera with the same focal lengths (radtan, equidistant), downscaled by `downscale`
/// (area averaging), colour kept, mono8 grey in all three channels. Fails for a depth image,
/// data that does not fill the image, or a size other than the intrinsics' (when they give one).
Result<PosedView> image_view(const msgs::ImageMessage& image, const msgs::CameraIntrinsics& intrinsics, const msgs::DistortionModel& distortion,
                             const SE3& T_world_camera, int downscale);

/// Sets the camera's R_camera_world and t_camera_world from T_world_camera.
void place_camera(SplatCamera& camera, const SE3& T_world_camera);

}  // namespace hanzo::fusion::neural
