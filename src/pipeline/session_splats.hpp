#pragma once
// SessionSplats: 3D Gaussian splats (neural/splat_trainer.hpp) trained while a Session runs,
// from one camera's images at the Session's poses (fusion.mapping.splats).
//
// Views: an image (at most one per 0.1 s of data) waits until the Frontend's estimate covers its
// time (body clock = image time + the camera's time offset); it becomes a view when the camera
// moved min_translation or turned min_rotation_degrees since the last view: downscaled to about
// image_width (neural::image_view: undistorted, area averaged), its pose T_world_camera =
// T_world_body(t) T_body_camera kept relative to the newest Frontend keyframe (its anchor), so
// that the view follows the keyframe graph's corrections (move_views), as map keyframes do.
// At most max_views views; beyond, the oldest is dropped.
//
// Gaussians: a scene that grows with the views. The points of the Session's map keyframes
// (add_points, world frame), one per seed_voxel cell, wait in a pool; each new view turns the
// pooled points it sees (in front of it, nearer than max_depth, inside the image) into Gaussians
// coloured by it (neural::initialize_gaussians_at_points, at most gaussians_per_view, an even
// selection); without map points (seed_from_map false: no LiDAR) each view gets
// gaussians_per_view / 4 at random pixels and random depths in [1, max_depth / 2] m. The
// Gaussians do not follow later graph corrections (the training moves them).
//
// Training (the trainer's Adam and density control with an open-ended schedule: densification
// throughout, up to twice the Gaussians the views seeded, at most max_gaussians; no opacity
// resets, which would blank the map a reader may fetch at any moment): each step renders one view, every fourth the newest, else one
// drawn at random.
//  - Replay (realtime false): steps_per_view steps after each new view, inside the caller, on
//    `threads` threads: the same messages give the same Gaussians, bit for bit.
//  - Realtime: a worker thread of its own trains continuously on one thread, idle for as long as
//    each step took times (1 / cpu_share - 1): at most cpu_share of one core. New views and
//    Gaussians reach it between steps.
//
// Frames: world = the Session's world; cameras in the OpenCV optical frame. Thread-safe as the
// Session uses it: one caller thread, plus the worker.

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::pipeline {

struct SessionSplatsConfig {
  config::SplatMappingConfig settings;  ///< fusion.mapping.splats
  bool realtime = false;
  int threads = 1;                      ///< replay: rasterizer threads (<= 0: every core)
  bool seed_from_map = true;            ///< Gaussians start at add_points' points (else random)
  double min_translation = 0.3;         ///< m between views
  double min_rotation_degrees = 10.0;
  std::size_t max_views = 300;
  int gaussians_per_view = 3000;
  double seed_voxel = 0.1;              ///< m: one pooled map point per cell
  double max_depth = 20.0;              ///< m: map points farther from a view are not seeded by it
  double scene_extent = 10.0;           ///< m: the trainer's learning-rate and density scale
  double image_interval_s = 0.1;        ///< images closer in time than this to the last taken are skipped
  uint64_t seed = 1;
};

struct SplatCameraModel {
  std::string sensor;
  msgs::CameraIntrinsics intrinsics;
  msgs::DistortionModel distortion;
  SE3 T_body_camera;
  Duration time_offset;  ///< t_body = t_camera + offset
};

struct SessionSplatsSummary {
  uint64_t views = 0;
  uint64_t iterations = 0;
  uint64_t gaussians = 0;
  uint64_t images_skipped = 0;  ///< without a pose (before the first keyframe) or unreadable
  double training_seconds = 0.0;  ///< realtime: the worker's stepping time (0 in replay)
};

class SessionSplats {
 public:
  /// Fails when the module is built without the AI module (HANZO_FUSION_AI), for intrinsics
  /// without a size or focal length, or settings out of range.
  static Result<std::unique_ptr<SessionSplats>> create(SplatCameraModel camera, SessionSplatsConfig config);
  ~SessionSplats();  ///< stops the worker
  SessionSplats(const SessionSplats&) = delete;
  SessionSplats& operator=(const SessionSplats&) = delete;

  const std::string& sensor() const;
  /// An image of the camera (valid, in time order: the Session checked it).
  void add_image(const msgs::ImageMessage& image);
  /// A map keyframe's points, world frame.
  void add_points(const std::vector<Eigen::Vector3f>& points_world);
  /// Images whose time `T_world_body_at` covers become views anchored to keyframe `anchor`
  /// (T_world_anchor: its pose now); replay trains after each.
  void take_views(const std::function<std::optional<SE3>(Timestamp)>& T_world_body_at, uint64_t anchor, const SE3& T_world_anchor);
  /// Views move with their anchors' poses (none: the anchor left the graph; the view stays).
  void move_views(const std::function<std::optional<SE3>(uint64_t)>& T_world_keyframe);
  /// The current Gaussians (none before the first view), provenance filled in.
  std::optional<msgs::GaussianSplatLayer> layer() const;
  SessionSplatsSummary summary() const;

 private:
  struct Impl;
  explicit SessionSplats(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace hanzo::fusion::pipeline
