#pragma once
// LoopClosureDetector: 3D LiDAR loop closure between keyframes (SC-LeGO-LOAM's scheme):
//  1. Candidate: the Scan Context database (scan_context.hpp; ring key then full distance, the
//     newest scan_context.exclude_recent keyframes excluded) proposes keyframe c for the newest
//     keyframe k; c must lie at least min_travel metres of path back and, by the caller's
//     current keyframe poses, within min_search_radius + search_radius_per_meter x (path
//     between them) of k (the drift the estimate can have gathered).
//  2. Verification: k's points are registered to a submap of keyframes c - submap_keyframes ..
//     c + submap_keyframes (older than k) in c's frame (surface_registration.hpp), first with
//     3x coarser voxels to pull in a guess metres off, then at the odometry's map resolution;
//     from the poses' relative pose, then from the descriptor's yaw alone. Accepted when it
//     converges with an inlier RMSE up to max_rmse, at least min_inlier_fraction of the points
//     matched and a translation that is not degenerate (LidarOdometryConfig::degeneracy_ratio).
// The detector keeps the keyframes' points (sensor frame) and path lengths; the poses stay the
// caller's (a pose graph's current estimate), passed to each call.
// Revisits: a keyframe within covered_distance / covered_angle of the path through keyframes at
// least min_travel of path older (covered()) is a view the detector already has; the caller searches
// it for a loop like any other and then drops it (remove_newest()), so that driving the same
// streets again and again does not grow the keyframes.
//
// Frames: T_world_keyframe maps keyframe sensor-frame points into the caller's world;
// LoopClosure::T_from_to maps points of keyframe `to` into keyframe `from`'s frame.
// Failure cases: add_keyframe rejects non-finite points and a path that decreases; verify
// returns an Error naming what failed (unknown keyframe, no convergence, RMSE, overlap).
#include <cstddef>
#include <functional>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/lidar/lidar_odometry.hpp"
#include "hanzo/fusion/lidar/scan_context.hpp"

namespace hanzo::fusion::lidar {

struct LoopClosureConfig {
  ScanContextConfig scan_context;
  double min_travel = 50.0;   ///< m of path between the two keyframes
  /// A candidate must lie within min + per_meter x (path between them) of the newest keyframe
  /// by the current estimate: the procedural city's streets look alike to Scan Context, which
  /// proposed 60 places 100-250 m away on the simulated drive.
  double min_search_radius = 10.0;    ///< m
  double search_radius_per_meter = 0.05;
  int submap_keyframes = 5;   ///< keyframes on each side of the candidate
  double max_rmse = 0.1;      ///< m
  double min_inlier_fraction = 0.5;
  /// A keyframe this close (m, rad) to the path between two successive keyframes at least
  /// min_travel of path older is a revisit (covered()). Keyframes come by time as well as by
  /// distance (one about every 7 m at 10 m/s on the simulated drive), so a retraced route
  /// passes between the older ones, not through them. 0 m: none is.
  double covered_distance = 1.0;
  double covered_angle = 0.2;
  double covered_max_spacing = 15.0;  ///< m; successive keyframes further apart cover only their own places
  Status validate() const;
};

struct LoopClosure {
  std::size_t from = 0;  ///< the older keyframe (the candidate)
  std::size_t to = 0;    ///< the newer keyframe
  SE3 T_from_to;
  double inlier_rmse = 0.0;      ///< m
  double inlier_fraction = 0.0;  ///< of k's registration points
};

/// One keyframe of a submap: its points (its sensor frame, must outlive the call) and its pose
/// in the submap's frame.
struct SubmapKeyframe {
  const std::vector<Eigen::Vector3f>* points = nullptr;
  SE3 T_submap_keyframe;
};

struct SubmapRegistration {
  SE3 T_submap_query;
  double inlier_rmse = 0.0;      ///< m
  double inlier_fraction = 0.0;  ///< of the query's registration points
};

/// The loop closures' verification (step 2 above) on its own: `query` (its sensor frame) is
/// registered to the submap from `guess` (T_submap_query), first with 3x coarser voxels, then at
/// odometry.map's resolution. Fails, naming the numbers, when it does not converge, the inlier
/// RMSE exceeds config.max_rmse, less than config.min_inlier_fraction of the points matched or
/// the translation is degenerate.
Result<SubmapRegistration> register_to_submap(const std::vector<SubmapKeyframe>& submap, const std::vector<Eigen::Vector3f>& query,
                                              const SE3& guess, const LoopClosureConfig& config, const LidarOdometryConfig& odometry);

class LoopClosureDetector {
 public:
  /// T_world_keyframe of keyframe k (the caller's current estimate).
  using PoseLookup = std::function<SE3(std::size_t keyframe)>;

  /// `odometry` supplies the map resolution, registration and degeneracy settings.
  LoopClosureDetector(LoopClosureConfig config, LidarOdometryConfig odometry);

  /// Adds keyframe number size(): its points (sensor frame) and the path travelled by then (m).
  Result<std::size_t> add_keyframe(std::vector<Eigen::Vector3f> points, double path);
  /// Whether a keyframe at T_world_query (path `path`, m) would be a revisit: within
  /// covered_distance of the segment between two successive keyframes (or of one keyframe) at
  /// least min_travel of path older and within covered_angle of the nearer one's orientation,
  /// by the caller's current poses.
  bool covered(const SE3& T_world_query, double path, const PoseLookup& T_world_keyframe) const;
  /// Forgets the newest keyframe (a revisit searched for a loop). No-op when there is none.
  void remove_newest();
  /// A verified loop closing at the newest keyframe, or none. Counts candidates.
  std::optional<LoopClosure> detect(const PoseLookup& T_world_keyframe);
  /// Registers keyframe `to` against the submap around keyframe `from` starting at guess
  /// T_from_to (manual loop closure: the caller knows roughly where it is).
  Result<LoopClosure> verify(std::size_t from, std::size_t to, const SE3& guess, const PoseLookup& T_world_keyframe) const;

  std::size_t size() const { return keyframes_.size(); }
  const std::vector<Eigen::Vector3f>& points(std::size_t keyframe) const { return keyframes_.at(keyframe).points; }
  double path(std::size_t keyframe) const { return keyframes_.at(keyframe).path; }
  std::size_t candidates() const { return candidates_; }  ///< descriptor matches in range so far
  const LoopClosureConfig& config() const { return config_; }

 private:
  struct Keyframe {
    std::vector<Eigen::Vector3f> points;
    double path = 0.0;
  };
  LoopClosureConfig config_;
  LidarOdometryConfig odometry_;
  ScanContextDatabase scan_contexts_;
  std::vector<Keyframe> keyframes_;
  std::optional<ScanContext> newest_descriptor_;
  std::size_t candidates_ = 0;
};

}  // namespace hanzo::fusion::lidar
