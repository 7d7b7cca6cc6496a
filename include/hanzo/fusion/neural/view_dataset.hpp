#pragma once
// Posed images for neural reconstruction, read from a NeRF / Blender-style `transforms.json`
// (the exchange format of NeRF, instant-ngp and nerfstudio):
//   camera_angle_x (horizontal field of view, radians) or fl_x / fl_y; optional cx, cy, w, h
//   (pixels, pixel centres at +0.5: cx = w / 2 is the image centre) and OpenCV distortion
//   k1, k2, p1, p2 (k3 too); frames[] with file_path (relative to the file; a path without an
//   extension gets ".png", Blender's convention) and transform_matrix, the camera-to-world 4 x 4
//   with the camera looking down -z, +y up (OpenGL). Per-frame fl_x, fl_y, cx, cy, w, h override.
// Images: 8-bit RGB or RGBA; RGBA is composited on `background` (the NeRF-synthetic protocol),
// and its alpha is kept as the foreground mask. Distorted images are undistorted to the pinhole
// camera with the same focal lengths. `downscale` divides the resolution (area averaging).
//
// Cameras come out as SplatCamera: OpenCV optical frame (x right, y down, z forward), pixel
// centres at integer coordinates.
//
// Failures (each an Error naming the file and field): a file that is not JSON, a missing or
// non-finite intrinsic or matrix, no frames, an image that cannot be read or whose size differs
// from the given w / h.

#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/neural/image_metrics.hpp"
#include "hanzo/fusion/neural/splat_rasterizer.hpp"

namespace hanzo::fusion::neural {

struct PosedView {
  std::string name;        ///< file_path as written
  SplatCamera camera;
  RgbImage image;          ///< empty when the dataset was read without images
  std::vector<float> mask;  ///< alpha 0..1 per pixel (RGBA inputs); empty otherwise
};

struct ViewDatasetConfig {
  int downscale = 1;  ///< resolution divided by this (1: as stored)
  Eigen::Vector3f background = Eigen::Vector3f::Ones();  ///< behind RGBA images' transparent pixels
  bool load_images = true;  ///< false: cameras only (rendering a poses file)
  int every = 1;            ///< keep every N-th frame (1: all)
  int skip_every = 0;       ///< drop every N-th frame (held-back views; 0: none), after `every`
  int only_every = 0;       ///< keep only every N-th frame (the held-back views; 0: all)
};

struct ViewDataset {
  std::vector<PosedView> views;
  /// Where the cameras look: the point nearest to every optical axis, and the mean camera
  /// distance from it (the scene's scale for learning rates and initialization).
  Eigen::Vector3d scene_centre = Eigen::Vector3d::Zero();
  double camera_distance = 1.0;
  double aabb_scale = 0.0;  ///< instant-ngp's scene-box scale when the file gives one (0: none)
  /// A box around what the views see, when the reader knows one (sensor logs; 0: none).
  Eigen::Vector3d box_centre = Eigen::Vector3d::Zero();
  double box_half_size = 0.0;
};

Result<ViewDataset> load_transforms(const std::string& path, const ViewDatasetConfig& config = {});

/// Writes `views`' cameras as a transforms.json (fl_x, fl_y, cx, cy, w, h per frame, no
/// distortion) with the given file paths.
Status save_transforms(const std::string& path, const std::vector<PosedView>& views, const std::vector<std::string>& file_paths);

/// The views at 1/factor of their resolution (images area-averaged, masks too, intrinsics scaled
/// about the pixel centres).
std::vector<PosedView> downscaled(const std::vector<PosedView>& views, int factor);

/// Renders every view that has an image (`render`: RGB floats at the camera's resolution) and
/// scores it against the image (PSNR, SSIM), with the rendering time per view.
EvaluationSummary score_views(const std::vector<PosedView>& views, const std::function<std::vector<float>(const SplatCamera&)>& render);

}  // namespace hanzo::fusion::neural
