#pragma once
// PlanarLaserSlam: SLAM for a 2D laser scanner on a ground robot (odometry + planar scans in,
// an optimized trajectory and a point map out). It only wires modules:
//
//   scan + odometry -> guess = last pose * odometry increment
//                   -> point-to-line ICP against a local map of the last keyframes
//                      (lidar/planar_icp.hpp); a correlative search (lidar/
//                      correlative_scan_matcher.hpp) when ICP fails or fits badly
//                   -> keyframe every keyframe_distance / keyframe_rotation: pose node X(k),
//                      between factor from the previous keyframe with the match's covariance
//                   -> loop closure: older keyframes near the new one (in the current
//                      estimate, far enough back along the path) are searched by correlative
//                      matching + ICP against their submap; a verified match becomes a between
//                      factor with a DCS kernel (graph/factor.hpp), so a wrong one switches itself off
//                   -> batch optimization (graph/batch_optimizer.hpp) after loop closures;
//                      the local map and the current pose follow the optimized keyframes.
//
// Frames: map = the frame of the first scan's odometry pose (the first scan is placed at its
// odometry pose, so a log's corrected poses and ours share a frame); T_map_laser per scan. The
// odometry frame is arbitrary: only increments between consecutive scans are used.
//
// Failure cases: a scan whose time does not increase, non-finite points or odometry, fewer
// than min_scan_points points: add_scan returns an Error and nothing changes. A scan that
// cannot be matched is placed by odometry alone (scan_matched = false, counted).

#include <cstddef>
#include <optional>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se2.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/graph/factor_graph.hpp"
#include "hanzo/fusion/graph/values.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/lidar/correlative_scan_matcher.hpp"
#include "hanzo/fusion/lidar/planar_icp.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::pipeline {

struct PlanarLaserSlamConfig {
  lidar::PlanarIcpConfig scan_matching;           ///< scan-to-map and loop-closure refinement
  /// Window searched when scan-to-map ICP fails (about the odometry error of one scan).
  lidar::CorrelativeScanMatcherConfig recovery_search{.linear_window = 0.5, .angular_window = 0.35, .resolution = 0.05,
                                                      .angular_step = 0.0175, .sigma = 0.1};
  int min_scan_points = 20;                ///< fewer points: the scan is refused
  double min_scan_matching_fitness = 0.5;  ///< below it a match is retried with the recovery search, then dropped
  /// Degenerate geometry (a corridor): when the match's translation_constraint_ratio
  /// (lidar/planar_icp.hpp) is below this, the scan is matched again with a prior on the
  /// odometry prediction (sigmas below), so the free direction follows odometry and the
  /// keyframe factor carries odometry's uncertainty along it. Counted in degenerate_scans.
  double degeneracy_ratio = 0.02;
  double keyframe_distance = 0.3;          ///< m travelled since the last keyframe
  double keyframe_rotation = 0.26;         ///< rad (15 deg) turned since the last keyframe
  int local_map_keyframes = 20;            ///< the newest keyframes form the scan-to-map target
  /// Added to the scan matcher's (optimistic) covariance of a keyframe's relative pose.
  double min_translation_sigma = 0.02;     ///< m
  double min_rotation_sigma = 0.005;       ///< rad
  /// Odometry's uncertainty (for unmatched and degenerate scans): sigma = these x the distance
  /// moved + the minimums.
  double odometry_translation_sigma_per_meter = 0.1;
  double odometry_rotation_sigma_per_meter = 0.05;  ///< rad per m

  bool loop_closure = true;
  double loop_search_radius = 4.0;      ///< m between the estimates of the new keyframe and a candidate
  double loop_min_travel = 10.0;        ///< m of path between a candidate and the new keyframe
  int loop_candidates = 2;              ///< nearest candidates tried per keyframe
  int loop_submap_keyframes = 5;        ///< the candidate +- this many keyframes form its target
  /// The loop-closure search; its windows are the largest searched. The windows used grow with
  /// the path driven since the last accepted loop closure (the drift the estimate may have
  /// gathered): min + per_meter x path, up to these. A window no larger than the drift keeps
  /// look-alike places (doors along a corridor) out of reach.
  lidar::CorrelativeScanMatcherConfig loop_search{.linear_window = 2.0, .angular_window = 0.35, .resolution = 0.05,
                                                  .angular_step = 0.0087, .sigma = 0.1};
  double loop_min_linear_window = 0.3;          ///< m
  double loop_linear_window_per_meter = 0.03;   ///< m per m of path
  double loop_min_angular_window = 0.05;        ///< rad
  double loop_angular_window_per_meter = 0.005; ///< rad per m of path
  double loop_min_fitness = 0.7;        ///< ICP fitness a loop closure needs (fraction of points matched)
  double loop_max_inlier_rmse = 0.05;   ///< m, point-to-line RMS a loop closure may have
  double loop_translation_sigma = 0.05; ///< m, added to a loop closure's matcher covariance
  double loop_rotation_sigma = 0.01;    ///< rad
  /// DCS parameter of loop closures. Too small and a loop closure that disagrees with a scan
  /// match that slipped is switched off instead of correcting it (intel: 5 -> 0.19 m APE,
  /// 50 -> 0.36 m); too large and the few wrong closures that pass verification pull the map
  /// apart (5000 -> 5.3 m). 200-1000 all give 0.08 m on intel.
  double loop_dcs_phi = 500.0;
  int optimization_iterations = 20;     ///< LM iterations after loop closures (warm started)

  Status validate() const;
};

struct PlanarScanEstimate {
  SE2 T_map_laser;                ///< on the graph's estimate after this scan (loop closures included)
  SE2 T_map_laser_matched;        ///< as the scan matcher found it, before a loop closure moved the graph
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  ///< of the match over (x, y, theta); odometry's when unmatched
  bool keyframe = false;          ///< the scan became keyframe X(keyframe_index)
  size_t keyframe_index = 0;      ///< the keyframe the scan belongs to
  bool scan_matched = false;      ///< false: placed by odometry alone
  bool degenerate = false;        ///< the scene left a direction free; odometry held it
  double fitness = 0.0;           ///< of the scan-to-map match
  int loop_closures_added = 0;
};

struct PlanarLaserSlamSummary {
  size_t scans = 0;
  size_t keyframes = 0;
  size_t recovered_matches = 0;       ///< scans matched only after the recovery search
  size_t unmatched_scans = 0;         ///< placed by odometry alone
  size_t degenerate_scans = 0;        ///< matched with the odometry prior along a free direction
  size_t loop_candidates = 0;         ///< candidate pairs searched
  size_t loop_closures = 0;           ///< verified and added
  size_t optimizations = 0;
  double final_chi2 = 0.0;            ///< of the last optimization (through the kernels)
  double scan_matching_seconds = 0.0;
  double loop_closure_seconds = 0.0;
  double optimization_seconds = 0.0;
};

class PlanarLaserSlam {
 public:
  explicit PlanarLaserSlam(PlanarLaserSlamConfig config = {});

  /// Adds a scan taken at `time` (points in the laser frame, m) with the laser's odometry pose
  /// at that time. Returns the scan's pose estimate.
  Result<PlanarScanEstimate> add_scan(Timestamp time, const lidar::PlanarPoints& points_laser, const SE2& T_odom_laser);
  /// The same for a planar point-cloud message (x, y of its points; z ignored).
  Result<PlanarScanEstimate> add_scan(const msgs::PointCloudMessage& scan, const SE2& T_odom_laser);

  /// Optimizes the whole graph to convergence (call once the log has ended).
  Status finish();

  /// T_map_laser of every scan added, through its keyframe's current estimate.
  io::Trajectory trajectory() const;
  /// Keyframe X(k), k < keyframe_count(): its scan's time, current pose estimate T_map_laser
  /// and points (laser frame). Map builders ray-cast these (maps/occupancy_grid.hpp).
  size_t keyframe_count() const { return keyframes_.size(); }
  Timestamp keyframe_time(size_t k) const { return keyframes_.at(k).time; }
  SE2 keyframe_pose(size_t k) const;
  const lidar::PlanarPoints& keyframe_points(size_t k) const { return keyframes_.at(k).points_laser; }
  const PlanarLaserSlamSummary& summary() const { return summary_; }
  const graph::FactorGraph& graph() const { return graph_; }
  const graph::Values& values() const { return values_; }

 private:
  struct Keyframe {
    Timestamp time;
    lidar::PlanarPoints points_laser;
    double path_length = 0.0;  ///< m of odometry path from the first scan
  };
  struct ScanRecord {
    Timestamp time;
    size_t keyframe = 0;
    SE2 T_keyframe_laser;
  };

  Result<lidar::PlanarTarget> local_map_target() const;
  struct Match {
    SE2 T_map_laser;
    Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();
    bool matched = false;
    bool degenerate = false;
    double fitness = 0.0;
    double constraint_ratio = 1.0;
  };
  Match match_scan(const lidar::PlanarPoints& points, const SE2& guess, double travelled);
  Status add_keyframe(Timestamp time, const lidar::PlanarPoints& points, const Match& match, double path_length);
  int close_loops();
  Status optimize(int max_iterations);

  PlanarLaserSlamConfig config_;
  PlanarLaserSlamSummary summary_;
  std::vector<Keyframe> keyframes_;
  std::vector<ScanRecord> scans_;
  graph::FactorGraph graph_;
  graph::Values values_;
  SE2 T_odom_last_;
  SE2 T_map_last_;
  double path_length_ = 0.0;
  double path_length_at_last_loop_closure_ = 0.0;
  std::optional<lidar::PlanarTarget> local_map_;  ///< rebuilt after keyframes / optimizations
};

}  // namespace hanzo::fusion::pipeline
