#include "visual_loop_closures.hpp"

namespace hanzo::fusion::pipeline {

VisualLoopClosures::VisualLoopClosures(vision::VisualLoopDetector detector, const SE3& T_body_camera, double place_distance, double place_angle)
    : detector_(std::move(detector)), T_body_camera_(T_body_camera), place_distance_(place_distance), place_angle_(place_angle) {}

Result<std::optional<VisualLoopClosures::LoopFactor>> VisualLoopClosures::add(Timestamp time, const cv::Mat& image, const vision::StaticMask& static_mask,
                                                                             const SE3& T_odometry_body, uint64_t anchor_keyframe, Timestamp anchor_time, const SE3& T_anchor_body) {
  if (!tracking_since_) tracking_since_ = time;
  if ((anchor_time - *tracking_since_).seconds() < kSettleSeconds) return std::optional<LoopFactor>();
  if (last_place_) {
    const SE3 since = last_place_->inverse() * T_odometry_body;
    if (since.translation().norm() < place_distance_ && since.rotation().log().norm() < place_angle_) return std::optional<LoopFactor>();
  }
  std::optional<vision::VisualLoop> loop;
  HANZO_ASSIGN_OR_RETURN(loop, detector_.add(image, T_odometry_body * T_body_camera_, static_mask));
  last_place_ = T_odometry_body;
  const Anchor offered{anchor_keyframe, T_anchor_body};
  if (static_cast<int>(anchors_.size()) < detector_.size()) anchors_.push_back(offered);  // kept as a place
  if (!loop) return std::optional<LoopFactor>();
  const Anchor& from = anchors_.at(static_cast<std::size_t>(loop->place));
  const Anchor& to = offered;
  // T_from_to = A T_place_current B with A = T_from_camera, B = T_camera_to; a right
  // perturbation of T_place_current is one of T_from_to by Ad(B^-1).
  const SE3 A = from.T_anchor_body * T_body_camera_;
  const SE3 B = T_body_camera_.inverse() * to.T_anchor_body.inverse();
  const auto adjoint = B.inverse().adjoint();
  LoopFactor factor{from.keyframe, to.keyframe, A * loop->T_place_current * B, adjoint * loop->covariance * adjoint.transpose(), *loop};
  return std::optional<LoopFactor>(factor);
}

}  // namespace hanzo::fusion::pipeline
