#pragma once
// VisualInertialFactors: the Session's keyframe graph as a visual-inertial problem (frontend.type
// msckf): between two keyframes an IMU preintegration factor and a bias random walk join the
// odometry's relative-motion factor (kept only as a weak anchor: odometry_covariance_scale),
// and features the tracker followed across
// keyframes become landmarks L(feature id) with Huber-robust projection factors, so that the
// graph re-estimates the whole trajectory from the raw measurements (as VINS-Fusion's and
// OKVIS's keyframe optimizations do) and loop closures pull it through the IMU and landmarks.
//
// Variables (graph/keys.hpp): X(k) = T_world_body of keyframe k (added by the KeyframeGraph),
// V(k) world velocity (m/s), B(k) the IMU's biases in body axes (imu_keyframe_chain.hpp: a
// keyframe the IMU cannot link starts a new chain, linked to the previous one by the odometry's
// relative motion at full weight), L(j) world points (m).
//
// Measurements: IMU samples of the body origin's motion in body axes on the body clock (the
// caller moves them through the calibration's imu_to_body); camera frames as the tracker's
// undistorted normalized observations. A keyframe (at an IMU sample's
// time) takes the last camera frame at most max_frame_gap_s before it: its observations are
// projected from the camera at T_keyframe_frame T_body_camera, T_keyframe_frame the body's
// motion over that gap (integrated from the IMU and the keyframe's velocity, held fixed).
//
// Landmarks: a track seen at two keyframes or more is triangulated from the odometry's poses of
// its frames (vision/feature_triangulation.hpp: locally the odometry's geometry is the best
// there is) and placed in the graph's world through its newest view's keyframe; it becomes a
// landmark when its views span min_parallax_rad and all reproject within
// max_reprojection_sigmas; the longest tracks first, at most max_new_landmarks per keyframe. A
// landmark gets a projection factor from every later keyframe that sees it. Projection noise:
// pixel_sigma at the camera's focal length. With a sliding window (KeyframeGraphConfig::
// window_keyframes) only views at the window's keyframes make landmarks, and a landmark
// marginalized with the keyframe that leaves the window gets no more projections.

#include <algorithm>
#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <set>
#include <vector>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"
#include "hanzo/fusion/graph/factor_graph.hpp"
#include "hanzo/fusion/graph/imu_preintegration.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"
#include "hanzo/fusion/vision/feature_observation.hpp"
#include "imu_keyframe_chain.hpp"

namespace hanzo::fusion::pipeline {

struct VisualInertialFactorsConfig {
  double pixel_sigma = 2.0;             ///< px: projection noise (the MSCKF's, for the KLT tracker)
  double huber_threshold = 1.345;       ///< Huber kernel of the projections, in sigmas
  int max_new_landmarks = 60;           ///< landmarks made per keyframe, longest tracks first
  double min_parallax_rad = 0.02;       ///< widest angle between a new landmark's viewing rays
  double min_depth_m = 0.2;             ///< a new landmark's depth in every view
  double max_depth_m = 60.0;
  double max_reprojection_sigmas = 3.0; ///< a new landmark's views must reproject within this
  double max_frame_gap_s = 0.1;         ///< the camera frame a keyframe uses is at most this older
  ImuChainPriors priors;                ///< V and B of the first keyframe of a chain
  /// Where the IMU links two keyframes the odometry's relative motion stays in the graph with
  /// its covariance scaled by this (standard deviations x10): a weak anchor that counts the
  /// odometry's measurements a hundredth a second time. On six simulated flights and walks it
  /// kept a start in motion from drifting off (ar_handheld from 6 s: 0.136 -> 0.101 m) and
  /// changed the others by under 0.015 m.
  double odometry_covariance_scale = 100.0;
};

class VisualInertialFactors {
 public:
  struct Camera {
    SE3 T_body_camera;
    double focal_length_px = 1.0;
    int rig = 0;  ///< cameras imaging together (a stereo pair) share a rig number
  };
  /// The factors a keyframe brings (its X(k) value and odometry factor are the KeyframeGraph's).
  struct KeyframeFactors {
    graph::GraphUpdate update;
    bool imu_factor = false;  ///< the IMU factor replaces the odometry's relative motion
    int new_landmarks = 0;
    int projections = 0;
  };
  /// cameras: 0 the left (or only) one, 1 the right one of a stereo rig, then those of further
  /// rigs (max_new_landmarks is per rig); imu: noise and gravity
  /// of the preintegration; random walks as the spec's accel_bias_random_walk (m/s^2/sqrt(s))
  /// and gyro_bias_random_walk (rad/s/sqrt(s)).
  VisualInertialFactors(std::vector<Camera> cameras, const graph::ImuPreintegrationConfig& imu, double accel_bias_random_walk,
                        double gyro_bias_random_walk, VisualInertialFactorsConfig config = {});

  /// An IMU sample of the body origin in body axes on the body clock; older or repeated samples
  /// are ignored.
  void add_imu(const estimate::ImuSample& sample);
  /// A tracked camera frame (body-clock time): the odometry's body pose in its own world, the
  /// features' undistorted normalized coordinates and the rigs whose images made it (empty: every
  /// rig). A keyframe takes each rig's last frame before it; a track or landmark ends when a
  /// frame of its rig that a keyframe takes no longer sees it.
  void add_frame(Timestamp time, const SE3& T_odometry_body, std::vector<vision::FeatureObservation> observations, std::vector<int> rigs = {});


  /// The factors of a new keyframe (its pose in the graph's world), given the graph's current
  /// estimate of the earlier ones. V(k) starts at the odometry's velocity (its poses around the
  /// keyframe's frame), else the IMU's prediction from the previous keyframe, else the
  /// keyframe's; B(k) at the previous keyframe's estimate, or bias_body (the odometry's IMU
  /// biases, body axes) for the first of a chain. An observation of
  /// a landmark gets a projection only where the estimates put the landmark in front of the
  /// camera (at least min_depth_m); one that is not ends the landmark (a projection behind the
  /// camera cannot be evaluated: the optimizer could not start from there).
  KeyframeFactors keyframe(const msgs::Keyframe& keyframe, const graph::ImuBias& bias_body, const graph::Values& estimate);
  /// The graph was replaced, or the last keyframe's factors were not added: the next keyframe
  /// starts a new chain, landmarks are forgotten.
  void restart();
  /// The odometry started again in a new world of its own: tracks before and after do not
  /// triangulate together (landmarks already made keep their place).
  void odometry_restarted();
  /// The graph keeps the variables of keyframes from `keyframe_id` on only (a sliding window):
  /// views at older keyframes no longer make landmarks (their poses left the window's factors).
  void set_window_start(uint64_t keyframe_id);
  /// Landmarks the graph marginalized: their later observations are not projected (the track
  /// does not become a landmark again).
  void forget_landmarks(const std::vector<uint64_t>& feature_ids);

 private:
  struct Frame {
    Timestamp time;
    SE3 T_odometry_body;
    std::vector<vision::FeatureObservation> observations;
    std::vector<int> rigs;  // empty: every rig
    bool images(int rig) const { return rigs.empty() || std::find(rigs.begin(), rigs.end(), rig) != rigs.end(); }
  };
  struct View {
    uint64_t keyframe;
    SE3 T_keyframe_frame;  // the body at the frame, in the keyframe's body frame
    SE3 T_odometry_body;   // the body at the frame, in the odometry's world
    int camera;
    Eigen::Vector2d normalized;
  };
  // The frame a keyframe at `keyframe_time` uses (for `rig`, or any): the last one at or before
  // it, at most max_frame_gap_s earlier (frames are tracked ahead of the Frontend's keyframes);
  // end() if none.
  std::deque<Frame>::const_iterator frame_for(Timestamp keyframe_time, std::optional<int> rig = std::nullopt) const;
  int rig_of(const View& view) const { return cameras_[static_cast<size_t>(view.camera)].rig; }
  void add_projection(KeyframeFactors& out, uint64_t feature, const View& view) const;
  // Whether the view's camera, with the body at T_world_keyframe, sees the point at least
  // min_depth_m in front.
  bool in_front(const View& view, const SE3& T_world_keyframe, const Eigen::Vector3d& point_world) const;
  void make_landmarks(KeyframeFactors& out, const SE3& T_world_keyframe, const SE3& T_world_odometry, const graph::Values& estimate);

  std::vector<Camera> cameras_;
  VisualInertialFactorsConfig config_;
  int rigs_ = 1;  // rig numbers 0 .. rigs_ - 1
  ImuKeyframeChain chain_;
  graph::GaussianNoise projection_noise_;  // pixel_sigma, both axes
  std::deque<Frame> frames_;  // the last seconds'
  std::map<uint64_t, std::vector<View>> tracks_;    // features seen at keyframes, not landmarks yet
  std::map<uint64_t, int> landmarks_;               // features with an L in the graph, still tracked: their rig
  std::set<uint64_t> made_;                         // every feature with an L in the graph
  uint64_t window_start_ = 0;                       // views at older keyframes make no landmarks
};

}  // namespace hanzo::fusion::pipeline
