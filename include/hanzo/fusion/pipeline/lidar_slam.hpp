#pragma once
// LidarSlam: 3D LiDAR SLAM = LidarOdometry + keyframe pose graph + Scan Context loop closure
// (the back end of LIO-SAM / SC-LeGO-LOAM, on this project's factor graph).
//
// Per sweep: LidarOdometry (lidar/lidar_odometry.hpp). Every keyframe_distance metres or
// keyframe_angle radians of odometry motion a keyframe is made: node X(k) with the odometry's
// pose, a between factor to X(k-1) with sigmas that grow with the distance, its deskewed points
// (sensor frame) and its Scan Context descriptor (Kim & Kim 2018). Loop closure:
//  1-2. lidar::LoopClosureDetector (lidar/loop_closure.hpp) proposes a candidate keyframe c by
//     Scan Context within the search radius of the graph's estimate and verifies it by
//     registering the new keyframe to the submap around c;
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
#include "hanzo/fusion/lidar/loop_closure.hpp"

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
  lidar::LoopClosureConfig loop;   ///< candidates and verification (lidar/loop_closure.hpp)
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
  const std::vector<Eigen::Vector3f>& keyframe_points(std::size_t k) const { return loop_closures_.points(k); }
  const LidarSlamSummary& summary() const { return summary_; }
  const lidar::LidarOdometry& odometry() const { return odometry_; }

 private:
  struct Keyframe {
    SE3 T_odometry;  ///< the odometry's pose when it was made
  };
  struct SweepRecord {
    Timestamp time;
    SE3 T_odometry;
    std::size_t keyframe = 0;
  };

  Status add_keyframe(const lidar::LidarOdometryEstimate& estimate);
  /// Tries to close a loop from the newest keyframe; true when a factor was added.
  bool close_loop();

  LidarSlamConfig config_;
  lidar::LidarOdometry odometry_;
  lidar::LoopClosureDetector loop_closures_;
  graph::FactorGraph graph_;
  graph::Values values_;
  std::vector<Keyframe> keyframes_;
  std::vector<SweepRecord> sweeps_;
  double path_ = 0.0;
  LidarSlamSummary summary_;
};

}  // namespace hanzo::fusion::pipeline
