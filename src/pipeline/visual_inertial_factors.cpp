#include "visual_inertial_factors.hpp"

#include <algorithm>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/graph/imu_factors.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/graph/projection_factors.hpp"
#include "hanzo/fusion/vision/feature_triangulation.hpp"

namespace hanzo::fusion::pipeline {
namespace {

constexpr double kFrameHistorySeconds = 2.0;   // frames kept (the Frontend's keyframes lag the images)

}  // namespace

VisualInertialFactors::VisualInertialFactors(std::vector<Camera> cameras, const graph::ImuPreintegrationConfig& imu, double accel_bias_random_walk,
                                             double gyro_bias_random_walk, VisualInertialFactorsConfig config)
    : cameras_(std::move(cameras)),
      config_(config),
      rigs_(cameras_.empty() ? 0 : 1 + std::max_element(cameras_.begin(), cameras_.end(), [](const Camera& a, const Camera& b) { return a.rig < b.rig; })->rig),
      chain_(imu, accel_bias_random_walk, gyro_bias_random_walk, config.priors),
      projection_noise_(graph::GaussianNoise::from_sigmas(Eigen::Vector2d::Constant(config.pixel_sigma)).value()) {}

void VisualInertialFactors::add_imu(const estimate::ImuSample& sample) { chain_.add_imu(sample); }

void VisualInertialFactors::add_frame(Timestamp time, const SE3& T_odometry_body, std::vector<vision::FeatureObservation> observations,
                                      std::vector<int> rigs) {
  if (!frames_.empty() && time <= frames_.back().time) return;
  frames_.push_back({time, T_odometry_body, std::move(observations), std::move(rigs)});
  while ((time - frames_.front().time).seconds() > kFrameHistorySeconds) frames_.pop_front();
}

std::deque<VisualInertialFactors::Frame>::const_iterator VisualInertialFactors::frame_for(Timestamp keyframe_time, std::optional<int> rig) const {
  for (auto it = frames_.rbegin(); it != frames_.rend(); ++it) {
    if (it->time > keyframe_time || (rig && !it->images(*rig))) continue;
    if ((keyframe_time - it->time).seconds() > config_.max_frame_gap_s) break;
    return std::prev(it.base());
  }
  return frames_.end();
}

void VisualInertialFactors::odometry_restarted() { tracks_.clear(); }

void VisualInertialFactors::set_window_start(uint64_t keyframe_id) {
  window_start_ = keyframe_id;
  for (auto it = tracks_.begin(); it != tracks_.end();) {
    std::erase_if(it->second, [keyframe_id](const View& view) { return view.keyframe < keyframe_id; });
    it = it->second.empty() ? tracks_.erase(it) : std::next(it);
  }
}

void VisualInertialFactors::forget_landmarks(const std::vector<uint64_t>& feature_ids) {
  for (const uint64_t feature : feature_ids) landmarks_.erase(feature);
}

void VisualInertialFactors::restart() {
  chain_.restart();
  window_start_ = 0;
  tracks_.clear();
  landmarks_.clear();
  made_.clear();
}

void VisualInertialFactors::add_projection(KeyframeFactors& out, uint64_t feature, const View& view) const {
  const double focal = cameras_[static_cast<size_t>(view.camera)].focal_length_px;
  PinholeCamera camera;
  camera.fx = camera.fy = focal;
  camera.min_depth = 1e-3;
  out.update.factors.emplace_robust<graph::ProjectionFactor>(graph::RobustKernel{graph::RobustKernel::Type::kHuber, config_.huber_threshold},
                                                             graph::X(view.keyframe), graph::L(feature), focal * view.normalized, camera,
                                                             view.T_keyframe_frame * cameras_[static_cast<size_t>(view.camera)].T_body_camera,
                                                             projection_noise_);
  ++out.projections;
}

bool VisualInertialFactors::in_front(const View& view, const SE3& T_world_keyframe, const Eigen::Vector3d& point_world) const {
  const SE3 T_world_camera = T_world_keyframe * view.T_keyframe_frame * cameras_[static_cast<size_t>(view.camera)].T_body_camera;
  return (T_world_camera.inverse() * point_world).z() >= config_.min_depth_m;
}

VisualInertialFactors::KeyframeFactors VisualInertialFactors::keyframe(const msgs::Keyframe& keyframe, const graph::ImuBias& bias_body,
                                                                       const graph::Values& estimate) {
  KeyframeFactors out;
  const uint64_t id = keyframe.keyframe_id;
  const SE3 T_world_body = keyframe.T_world_body.to_se3();
  // Linked to the previous keyframe by the IMU.
  const ImuKeyframeChain::Link link = chain_.link(keyframe, bias_body, estimate, out.update);
  out.imu_factor = link.imu_factor;
  Eigen::Vector3d velocity = link.velocity;
  // The camera frame just before the keyframe, and the body's motion from the keyframe back to it.
  const auto frame = frame_for(keyframe.timestamp);
  const std::optional<SE3> T_keyframe_frame = frame != frames_.end() ? chain_.body_motion(keyframe, link.bias, frame->time) : std::nullopt;
  // The velocity: the odometry's (its poses around the frame, in the graph's world) where there
  // are frames on both sides, else the IMU's prediction, else the keyframe's.
  if (T_keyframe_frame) {
    if (frame != frames_.begin() && std::next(frame) != frames_.end()) {
      const Frame& before = *std::prev(frame);
      const Frame& after = *std::next(frame);
      const double span = (after.time - before.time).seconds();
      if (span > 0.0 && span <= 2.0 * config_.max_frame_gap_s) {
        const SO3 R_world_odometry = (T_world_body * *T_keyframe_frame * frame->T_odometry_body.inverse()).rotation();
        velocity = R_world_odometry * ((after.T_odometry_body.translation() - before.T_odometry_body.translation()) / span);
      }
    }
  }
  chain_.close(keyframe, velocity, link, out.update);

  // The frames the keyframe takes: each rig's last one (one frame when the rigs image together),
  // and their observations from the keyframe's body.
  std::vector<std::pair<std::deque<Frame>::const_iterator, std::vector<int>>> taken;  // a frame, the rigs it is taken for
  for (int rig = 0; rig < rigs_; ++rig) {
    const auto rig_frame = frame_for(keyframe.timestamp, rig);
    if (rig_frame == frames_.end()) continue;
    const auto same = std::find_if(taken.begin(), taken.end(), [&rig_frame](const auto& entry) { return entry.first == rig_frame; });
    if (same != taken.end()) {
      same->second.push_back(rig);
    } else {
      taken.push_back({rig_frame, {rig}});
    }
  }
  std::set<uint64_t> seen;
  std::set<int> rigs_taken;
  std::optional<std::pair<Timestamp, SE3>> T_world_odometry;  // from the newest frame taken
  for (const auto& [rig_frame, rigs] : taken) {
    const std::optional<SE3> T_keyframe_rig_frame = chain_.body_motion(keyframe, link.bias, rig_frame->time);
    if (!T_keyframe_rig_frame) continue;
    rigs_taken.insert(rigs.begin(), rigs.end());
    if (!T_world_odometry || rig_frame->time > T_world_odometry->first) {
      T_world_odometry.emplace(rig_frame->time, T_world_body * *T_keyframe_rig_frame * rig_frame->T_odometry_body.inverse());
    }
    for (const vision::FeatureObservation& observation : rig_frame->observations) {
      if (observation.camera < 0 || observation.camera >= static_cast<int>(cameras_.size())) continue;
      const View view{id, *T_keyframe_rig_frame, rig_frame->T_odometry_body, observation.camera, observation.normalized};
      if (std::find(rigs.begin(), rigs.end(), rig_of(view)) == rigs.end()) continue;
      if (landmarks_.count(observation.feature_id) != 0) {
        const Result<Eigen::Vector3d> point = estimate.at<Eigen::Vector3d>(graph::L(observation.feature_id));
        if (!point || !in_front(view, T_world_body, *point)) continue;  // the landmark ends
        add_projection(out, observation.feature_id, view);
      } else {
        tracks_[observation.feature_id].push_back(view);
      }
      seen.insert(observation.feature_id);
    }
  }
  if (!rigs_taken.empty()) {
    // Tracks that ended in their rig's frame never come back (the tracker does not reuse ids).
    const auto ended = [&](uint64_t feature, int rig) { return rigs_taken.count(rig) != 0 && seen.count(feature) == 0; };
    for (auto it = tracks_.begin(); it != tracks_.end();) it = ended(it->first, rig_of(it->second.front())) ? tracks_.erase(it) : std::next(it);
    for (auto it = landmarks_.begin(); it != landmarks_.end();) it = ended(it->first, it->second) ? landmarks_.erase(it) : std::next(it);
    make_landmarks(out, T_world_body, T_world_odometry->second, estimate);
  }
  return out;
}

void VisualInertialFactors::make_landmarks(KeyframeFactors& out, const SE3& T_world_keyframe, const SE3& T_world_odometry,
                                           const graph::Values& estimate) {
  // Tracks seen at two keyframes or more, the longest first.
  std::vector<std::pair<size_t, uint64_t>> candidates;
  for (const auto& [feature, views] : tracks_) {
    if (views.front().keyframe != views.back().keyframe && made_.count(feature) == 0) candidates.emplace_back(views.size(), feature);
  }
  std::sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) { return a.first > b.first || (a.first == b.first && a.second < b.second); });
  vision::FeatureTriangulationConfig triangulation;
  triangulation.min_depth = config_.min_depth_m;
  triangulation.max_depth = config_.max_depth_m;
  triangulation.min_parallax_rad = config_.min_parallax_rad;
  for (const auto& [length, feature] : candidates) {
    if (out.new_landmarks >= config_.max_new_landmarks * rigs_) break;
    const std::vector<View>& views = tracks_.at(feature);
    std::vector<vision::FeatureView> feature_views;
    for (const View& view : views) {
      feature_views.push_back({view.T_odometry_body, cameras_[static_cast<size_t>(view.camera)].T_body_camera, view.normalized});
    }
    const std::optional<Eigen::Vector3d> point_odometry = vision::triangulate_feature(feature_views, triangulation);
    if (!point_odometry) continue;
    bool consistent = true;
    for (size_t k = 0; k < views.size() && consistent; ++k) {
      const Eigen::Vector3d p_camera = (feature_views[k].T_world_body * feature_views[k].T_body_camera).inverse() * *point_odometry;
      const double focal = cameras_[static_cast<size_t>(views[k].camera)].focal_length_px;
      consistent = focal * (p_camera.head<2>() / p_camera.z() - views[k].normalized).norm() <= config_.max_reprojection_sigmas * config_.pixel_sigma;
    }
    if (!consistent) continue;
    // In the graph's world every view must see it in front (its keyframes' estimates there may
    // have moved from the odometry's poses).
    const Eigen::Vector3d point_world = T_world_odometry * *point_odometry;
    for (size_t k = 0; k < views.size() && consistent; ++k) {
      const Result<SE3> T_world_view = views[k].keyframe == views.back().keyframe ? Result<SE3>(T_world_keyframe) : estimate.at<SE3>(graph::X(views[k].keyframe));
      consistent = T_world_view && in_front(views[k], *T_world_view, point_world);
    }
    if (!consistent) continue;
    out.update.values.insert(graph::L(feature), point_world);
    for (const View& view : views) add_projection(out, feature, view);
    ++out.new_landmarks;
    landmarks_.emplace(feature, rig_of(views.front()));
    made_.insert(feature);
    tracks_.erase(feature);  // (views is not used after this)
  }
}

}  // namespace hanzo::fusion::pipeline
