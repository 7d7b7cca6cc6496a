#pragma once
// VisualLoopClosures: the Session's loop closures from the camera when the odometry keeps no
// map of its own (frontend.type msckf). Camera frames become places of a
// vision::VisualLoopDetector every place_distance metres or place_angle radians of the
// odometry's motion; each place is anchored to the Frontend keyframe before it, with the body's
// pose relative to that keyframe (as the LiDAR map keyframes are), so that a verified loop
// between two places becomes a loop factor between their two keyframes in the KeyframeGraph.
//
// A place is made only once the camera has tracked without a lost frame for kSettleSeconds
// before its anchor keyframe: after a loss (darkness) the odometry's corrections move the
// Frontend for a while, and the Frontend's motion from the anchor to the place (part of the
// factor) would carry them.
//
// Frames: T_odometry_body in the odometry's own world (only its short relative motions are
// used); T_anchor_body in the Frontend's world before its corrections; T_body_camera the
// camera's mounting. The factor: T_from_to between the anchors, covariance over its tangent
// (rho, phi), right perturbation, carried from the loop's camera frame by the adjoint.

#include <cstdint>
#include <optional>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/vision/visual_loop_detector.hpp"

namespace hanzo::fusion::pipeline {

class VisualLoopClosures {
 public:
  struct LoopFactor {
    uint64_t from_keyframe = 0;
    uint64_t to_keyframe = 0;
    SE3 T_from_to;
    Eigen::Matrix<double, 6, 6> covariance;
    vision::VisualLoop loop;
  };

  VisualLoopClosures(vision::VisualLoopDetector detector, const SE3& T_body_camera, double place_distance, double place_angle);

  /// Offers a tracked frame (8-bit grey image, its moving objects' static mask) at `time`; a
  /// place is made when the odometry moved enough since the last one. Returns the loop factor a
  /// verified loop gives.
  Result<std::optional<LoopFactor>> add(Timestamp time, const cv::Mat& image, const vision::StaticMask& static_mask, const SE3& T_odometry_body,
                                        uint64_t anchor_keyframe, Timestamp anchor_time, const SE3& T_anchor_body);
  /// A frame the odometry lost: tracking must settle again before the next place.
  void note_lost() { tracking_since_.reset(); }

  int places() const { return detector_.size(); }
  int candidates_checked() const { return detector_.candidates_checked(); }
  int loops() const { return detector_.loops(); }

 private:
  struct Anchor {
    uint64_t keyframe;
    SE3 T_anchor_body;
  };
  vision::VisualLoopDetector detector_;
  SE3 T_body_camera_;
  double place_distance_;
  double place_angle_;
  static constexpr double kSettleSeconds = 2.0;
  std::optional<Timestamp> tracking_since_;  // first tracked frame after the last lost one
  std::optional<SE3> last_place_;  // T_odometry_body of the last place
  std::vector<Anchor> anchors_;    // per place
};

}  // namespace hanzo::fusion::pipeline
