#pragma once
// A vision pipeline's output on the cameras projected onto LiDAR points (HIP-0081 into the
// map): each point of a sweep takes the segmentation class of the pixel it projects onto, and
// is marked moving where it projects into a moving object's mask (detections or segmentation
// pixels of fusion.vision.dynamic_objects.classes, dynamic_mask.hpp).
//
// Frames and time: points are in the LiDAR frame at the sweep's time (body clock). For each
// camera the output nearest the sweep's time within max_gap is used; the points are moved into
// the camera at that image's time through the body's motion between the two times (the
// Frontend's poses; none known: no motion), T_camera_lidar = T_body_camera^-1
// T_world_body(t_image)^-1 T_world_body(t_sweep) T_body_lidar, and projected through the
// camera's lens model to the nearest pixel. Where several cameras see a point the first (in
// configuration order) with a class gives it; a point is moving when any camera's mask says so.
//
// Failure cases: no occlusion test (a point the camera cannot see, hidden behind a nearer
// surface, takes the nearer surface's class: LiDAR and camera close together keep this to
// object edges); outputs older than max_gap are not used (the points stay unlabelled).

#include <deque>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/map_messages.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::pipeline {

class SemanticProjection {
 public:
  struct Camera {
    std::string sensor;
    PinholeCamera lens;
    SE3 T_body_camera;
    Duration time_offset;  ///< t_body = t_camera + offset
    cv::Size image_size;
  };
  /// A sweep's points: a class per point (the map's class indices, msgs::kNoClass where no
  /// camera's segmentation saw it) and whether it lies on a moving object; both empty while no
  /// camera has sent an output.
  struct Labelled {
    std::vector<uint16_t> classes;
    std::vector<uint8_t> moving;  ///< 1 on a moving object
    std::size_t labelled = 0;     ///< points with a class
    std::size_t moving_points = 0;
  };

  SemanticProjection(std::vector<Camera> cameras, const SE3& T_body_lidar, config::DynamicObjectsConfig dynamic_objects);

  const Camera* camera(std::string_view sensor) const;
  /// Keeps a camera's output (validated, of the camera's image size): its segmentation with
  /// each class name mapped through class_index (the map's label table), its moving-object mask.
  void add(const Camera& camera, const msgs::DetectionsMessage& output, const std::function<uint16_t(std::string_view)>& class_index);
  /// Classes and moving flags of a sweep's points (LiDAR frame, sweep_time on the body clock);
  /// pose_at: T_world_body at a body-clock time, when known.
  Labelled label(Timestamp sweep_time, const std::vector<Eigen::Vector3f>& points_lidar,
                 const std::function<std::optional<SE3>(Timestamp)>& pose_at) const;

  /// Outputs further than this from a sweep are not used for it.
  static constexpr double kMaxGap_s = 0.1;

 private:
  struct Output {
    Timestamp body_time;
    std::vector<uint16_t> classes;  ///< per pixel, map class indices; empty without a segmentation
    cv::Mat static_mask;            ///< 0 on moving objects; empty when nothing moves
  };
  std::vector<Camera> cameras_;
  SE3 T_body_lidar_;
  config::DynamicObjectsConfig dynamic_objects_;
  std::vector<std::deque<Output>> outputs_;  ///< per camera, oldest first
};

}  // namespace hanzo::fusion::pipeline
