#pragma once
// LidarSlam: 3D LiDAR SLAM = LidarOdometry + keyframe pose graph + Scan Context loop closure
// (the back end of LIO-SAM / SC-LeGO-LOAM, on this project's factor graph).
//
// Per sweep: LidarOdometry (lidar/lidar_odometry.hpp). Every keyframe_distance metres or
// keyframe_angle radians of odometry motion a keyframe is made: node X(k) with the odometry's
// pose, a between factor to X(k-1) with sigmas that grow with the distance, its deskewed points
// (sensor frame) and its Scan Context descriptor (Kim & Kim 2018). Loop closure:
//  1. the descriptor database (lidar/scan_context.hpp; ring key then full distance, the newest
//     scan_context.exclude_recent keyframes excluded) proposes keyframe c; c must lie at least
//     loop_min_travel metres of path back and, by the graph, within the search radius;
//  2. geometric verification: the keyframe's points are registered to a submap of keyframes
//     c - loop_submap_keyframes .. c + loop_submap_keyframes in c's frame
//     (lidar/surface_registration.hpp), first from the graph's current relative pose, then from
//     the descriptor's yaw alone; accepted when it converges with an inlier RMSE up to
//     loop_max_rmse, at least loop_min_inlier_fraction of the points matched and a
//     non-degenerate translation;
//  3. a between factor X(c) -> X(k) with loop sigmas under a DCS kernel (Agarwal et al. 2013;
//     phi loop_dcs_phi), then batch Levenberg-Marquardt over the keyframe graph (X(0) fixed).
// trajectory() gives every sweep's pose corrected by its keyframe's optimized pose. The local
// map of the odometry is not moved by loop closures (it is local); the corrected keyframes are
// the global map.
//
// Frames: world = the first sweep's pose (initial_pose). Failure cases: those of LidarOdometry
// (returned, state unchanged); a failed verification or optimization is counted, not an error.

#include <cstddef>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/graph/factor_graph.hpp"
#include "hanzo/fusion/graph/values.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/lidar/lidar_odometry.hpp"
#include "hanzo/fusion/lidar/scan_context.hpp"

namespace hanzo::fusion::pipeline {

struct LidarSlamConfig {
  lidar::LidarOdometryConfig odometry;
  double keyframe_distance = 2.0;  ///< m
  double keyframe_angle = 0.2;     ///< rad
  /// Between-factor sigmas: min + per_meter x distance between the keyframes.
  double min_translation_sigma = 0.02;               ///< m
  double translation_sigma_per_meter = 0.01;
  double min_rotation_sigma = 0.002;                 ///< rad
  double rotation_sigma_per_meter = 0.0005;          ///< rad/m
  bool loop_closure = true;
  lidar::ScanContextConfig scan_context;
  double loop_min_travel = 50.0;   ///< m of path between the two keyframes
  /// A candidate must lie within min + per_meter x (path between them) of the newest keyframe
  /// by the graph's estimate (the drift it can have): the procedural city's streets look alike
  /// to Scan Context, which proposed 60 places 100-250 m away on the simulated drive.
  double loop_min_search_radius = 10.0;    ///< m
  double loop_search_radius_per_meter = 0.05;
  int loop_submap_keyframes = 5;   ///< keyframes on each side of the candidate
  double loop_max_rmse = 0.1;      ///< m
  double loop_min_inlier_fraction = 0.5;
  double loop_translation_sigma = 0.05;  ///< m
  double loop_rotation_sigma = 0.005;    ///< rad
  /// DCS phi: large, because a correct closure after a long loop is far off the drifted graph
  /// (3 m at 5 cm sigma: chi2 ~ 4000), which a small phi treats as an outlier; verification and
  /// the search radius keep wrong closures out.
  double loop_dcs_phi = 1e5;

  Status validate() const;
};

struct LidarSlamSummary {
  std::size_t scans = 0;
  std::size_t keyframes = 0;
  std::size_t loop_candidates = 0;  ///< descriptor matches far enough back
  std::size_t loop_closures = 0;    ///< verified and added
  std::size_t optimizations = 0;
  double odometry_seconds = 0.0;
  double loop_closure_seconds = 0.0;
  double optimization_seconds = 0.0;
};

class LidarSlam {
 public:
  explicit LidarSlam(LidarSlamConfig config = {}, const SE3& initial_pose = SE3());

  /// One sweep (see LidarOdometry::add_scan). The estimate is the odometry's.
  Result<lidar::LidarOdometryEstimate> add_scan(Timestamp time, const cloud::PointCloud& scan);

  /// Every accepted sweep's T_world_lidar (at the middle of the sweep), corrected by the
  /// optimized pose of the keyframe at or before it.
  io::Trajectory trajectory() const;
  std::size_t keyframe_count() const { return keyframes_.size(); }
  SE3 keyframe_pose(std::size_t k) const;
  /// The keyframe's deskewed points in its sensor frame.
  const std::vector<Eigen::Vector3f>& keyframe_points(std::size_t k) const { return keyframes_.at(k).points; }
  const LidarSlamSummary& summary() const { return summary_; }
  const lidar::LidarOdometry& odometry() const { return odometry_; }

 private:
  struct Keyframe {
    SE3 T_odometry;  ///< the odometry's pose when it was made
    std::vector<Eigen::Vector3f> points;
    double path = 0.0;  ///< m travelled by then
  };
  struct SweepRecord {
    Timestamp time;
    SE3 T_odometry;
    std::size_t keyframe = 0;
  };

  Status add_keyframe(const lidar::LidarOdometryEstimate& estimate);
  /// Tries to close a loop from the newest keyframe; true when a factor was added.
  bool close_loop();
  Result<SE3> verify(std::size_t candidate, std::size_t newest, const SE3& guess) const;

  LidarSlamConfig config_;
  lidar::LidarOdometry odometry_;
  lidar::ScanContextDatabase scan_contexts_;
  graph::FactorGraph graph_;
  graph::Values values_;
  std::vector<Keyframe> keyframes_;
  std::vector<SweepRecord> sweeps_;
  double path_ = 0.0;
  LidarSlamSummary summary_;
};

}  // namespace hanzo::fusion::pipeline
