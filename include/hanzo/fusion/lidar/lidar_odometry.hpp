#pragma once
// LidarOdometry: scan-to-local-map LiDAR odometry for spinning LiDARs (the pipeline of
// KISS-ICP, Vizzo et al. 2023, with surface-aware residuals and a degeneracy prior).
//
// Per scan (points in the sensor frame, per-point times from the scan timestamp):
//  1. Prediction of T_world_lidar: the last pose times the motion since the previous scan,
//     the caller's (T_previous_current between the sweep middles, from an IMU-propagated
//     filter in LiDAR-inertial mode) or the constant-velocity model's (the last motion
//     repeated). A motion, not an absolute pose: the odometry's frame then never has to agree
//     with the caller's.
//  2. Deskewing: each point is moved into the sensor frame at the middle of the sweep
//     (sweep_motion.hpp; needs point times, scans without them are used as they are): with the
//     caller's sampled motion during the sweep (LiDAR-inertial: the IMU-propagated filter's
//     poses every IMU period), else with a constant twist that follows the registration's
//     estimate (deskew_coupling): the twist between the previous pose and the prediction,
//     corrected as the estimate moves from the prediction. Poses refer to the middle of the
//     sweep: a velocity error then warps the sweep symmetrically instead of shifting it, which
//     would feed back through the constant-velocity model.
//  3. Range crop, lone near returns (rain drops, fog) dropped and the sweep flagged
//     weather_degraded when they or missing returns are many, voxel downsampling: map points
//     at the map's point spacing, registration points at source_voxel_size (KISS's double
//     downsampling).
//  4. Registration against the cloud::VoxelHashMap by Gauss-Newton on SE3 (right
//     perturbation). Each point is matched to the best of the surfaces of its voxel and the six
//     face neighbours: a planar voxel gives a point-to-plane residual, a line voxel close to
//     vertical (poles, trunks, corners) a point-to-line residual. Other shapes give none:
//     lines that are not vertical are mostly one ring's arc over the ground or a facade (a
//     point-to-line residual on them pulls a moving sensor back toward where that ring was),
//     volumes (foliage) have no stable surface. Geman-McClure weights. A weak prior on the
//     prediction is worth less than one matched point where the geometry
//     constrains the pose and keeps the prediction along directions it does not (a bare
//     corridor or street along its axis: degeneracy, Zhang et al., ICRA 2016).
//  5. Degeneracy: the eigenvalues of the translation block of the registration information
//     (Schur complement of the rotation); constraint_ratio = smallest / largest. Below
//     degeneracy_ratio the scan is flagged degenerate (the estimate then follows the
//     prediction along the weak direction, and its covariance says so).
//  6. The deskewed map points enter the local map at the estimated pose; voxels beyond
//     map.max_distance are dropped.
//
// Frames: world = the odometry frame (the first scan's sensor pose unless initial_pose is
// given); T_world_lidar maps sensor-frame points at the scan time into it. Units m, s, rad.
// Failure cases (returned Errors, state unchanged): time not after the previous scan, an
// invalid cloud, fewer than min_points after cropping, a non-finite predicted motion, too few
// matched points (< min_correspondences: no overlap with the map, e.g. after a teleport).

#include <cstddef>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/cloud/scan_normals.hpp"
#include "hanzo/fusion/cloud/voxel_hash_map.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/lidar/surface_registration.hpp"
#include "hanzo/fusion/lidar/sweep_motion.hpp"

namespace hanzo::fusion::lidar {

struct LidarOdometryConfig {
  double min_range = 1.0;              ///< m: closer returns (the vehicle itself) are dropped
  double max_range = 100.0;            ///< m
  bool deskew = true;
  /// Constant-twist deskewing (no sweep motion from the caller; from the third sweep): the
  /// twist that deskews the sweep follows the registration's estimate T, per tangent half with
  /// its factor c: twist(T) = c Log(T_previous^-1 T) / interval - (c - 1) previous twist
  /// (lidar::DeskewCoupling). 1.5: the twist at the sweep's middle under constant acceleration
  /// (the last interval's mean twist plus half its change from the interval before); 1: the
  /// mean twist; 0: the predicted twist throughout. A turn onset or a handheld sensor's swing
  /// then finds its own turn rate in one registration. The translation is not coupled by
  /// default: on a swung handheld sensor with 0.25 m map voxels any translation coupling (0.5-1.5)
  /// drifted 0.7-1.9 m RMSE over 40 s against 5 cm without; on cars 1.0-1.5 drift a little less
  /// (docs/lidar-odometry.md).
  double deskew_translation_coupling = 0.0;
  double deskew_rotation_coupling = 1.5;
  cloud::ScanNormalConfig normals;     ///< surface normals from the scan's rings (needs ring ids)
  /// The local map: 1 m voxels (also the neighbour search cells), up to 20 points each,
  /// 0.22 m apart; 100 m around the sensor.
  cloud::VoxelHashMapConfig map{.voxel_size = 1.0, .max_points_per_voxel = 20, .min_point_spacing = -1.0, .max_distance = 100.0};
  double source_voxel_size = 1.0;      ///< m: registration points (1.0 outdoor; 0.25 indoor)
  /// Scan-to-map registration (surface_registration.hpp): surfaces from the 10 nearest map
  /// points within 1 m, gate 0.5 m, Geman-McClure 0.1 m, prior 1 m / 0.1 rad on the
  /// prediction, vertical lines within 0.35 rad of z (the world frame's z must be up:
  /// initial_pose levels it), converged at steps under 5 mm and 1e-4 rad (the last
  /// iterations of a sweep whose weakly constrained direction creeps 2-5 mm a step under the
  /// kernel's reweighting added up to 30 iterations, and moved it no closer to the truth:
  /// KITTI drift 0.018 -> 0.016 % on the simulated HDL-64E drive).
  SurfaceRegistrationConfig registration{.translation_tolerance = 0.005, .neighbours = 10};
  double degeneracy_ratio = 0.02;      ///< constraint_ratio below: degenerate
  /// Rain, fog, dust: returns closer than phantom_max_range with no neighbour in the range image
  /// within phantom_max_gap are dropped (drops in the air; they would enter the map otherwise).
  /// The sweep is flagged weather_degraded when such phantoms exceed weather_phantom_fraction of
  /// its returns or its returns fall below weather_return_ratio of the running average
  /// (dropouts, short visibility).
  double phantom_max_range = 3.0;      ///< m
  double phantom_max_gap = 0.3;        ///< m
  double weather_phantom_fraction = 0.005;
  double weather_return_ratio = 0.8;
  std::size_t min_points = 100;        ///< points after cropping
  /// Threads for the preprocessing (range image, deskew) and the
  /// registration (its registration.num_threads is replaced by this); 1: the calling thread
  /// only, <= 0: every core. Results do not depend on it.
  int num_threads = 1;

  /// Ok, or an Error naming the first invalid field.
  Status validate() const;
};

/// The outcome of one scan.
struct LidarOdometryEstimate {
  /// The middle of the sweep (scan time + half the largest point time; the scan time when
  /// points carry no times): the estimate refers to it.
  Timestamp time;
  SE3 T_world_lidar;                   ///< at `time`
  SE3 T_previous_current;              ///< motion since the previous scan (identity for the first)
  /// Covariance of T_world_lidar's registration in its tangent (x, y, z, rx, ry, rz), right
  /// perturbation: the inverse registration information scaled by the residual variance,
  /// without the prior (large along degenerate directions).
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
  double constraint_ratio = 0.0;       ///< smallest / largest translation information eigenvalue
  bool degenerate = false;
  bool first_scan = false;             ///< the scan that started the map (no registration)
  int iterations = 0;
  int associations = 0;                ///< surface fits during registration
  bool converged = false;
  std::size_t source_points = 0;       ///< registration points
  std::size_t correspondences = 0;
  std::size_t plane_correspondences = 0;
  std::size_t line_correspondences = 0;
  double inlier_rmse = 0.0;            ///< m, RMS of matched residuals
  std::size_t map_points = 0;          ///< after adding this scan
  std::size_t phantom_points = 0;      ///< lone near returns dropped (see the config)
  double return_ratio = 1.0;           ///< returns in range / the running average
  bool weather_degraded = false;
  /// Wall-clock seconds of the stages: crop + downsampling + normals + deskew, registration,
  /// map update.
  double preprocess_seconds = 0.0;
  double registration_seconds = 0.0;
  double map_update_seconds = 0.0;
};

class LidarOdometry {
 public:
  explicit LidarOdometry(LidarOdometryConfig config = {}, const SE3& initial_pose = SE3());

  /// One scan (sensor frame; `times` relative to `time` when present). predicted_motion:
  /// T_previous_current of the sensor between the previous and this sweep's middles (ignored
  /// for the first scan). sweep_motion: the sensor's motion during the sweep with the middle of
  /// the sweep as reference (times from `time`), used to deskew instead of the constant twist.
  /// See the header comment for the steps and failure cases.
  Result<LidarOdometryEstimate> add_scan(Timestamp time, const cloud::PointCloud& scan,
                                         const std::optional<SE3>& predicted_motion = std::nullopt,
                                         const std::optional<SweepMotion>& sweep_motion = std::nullopt);

  /// Adds points seen before (world frame, from a sensor at sensor_origin; no normals) to the
  /// local map, e.g. a restarted session's stored keyframes: the next scans register against
  /// them (a first scan too, which then is registered rather than taken as the map's start).
  void add_map_points(const std::vector<Eigen::Vector3f>& points_world, const Eigen::Vector3d& sensor_origin) {
    map_.add(points_world, {}, sensor_origin);
  }

  /// The latest T_world_lidar (initial_pose before the first scan).
  const SE3& pose() const { return pose_; }
  const cloud::VoxelHashMap& local_map() const { return map_; }
  const LidarOdometryConfig& config() const { return config_; }
  std::size_t scans() const { return scans_; }
  std::size_t degenerate_scans() const { return degenerate_scans_; }
  std::size_t weather_degraded_scans() const { return weather_degraded_scans_; }
  /// The last scan's deskewed map points in the sensor frame (empty before the first scan).
  const std::vector<Eigen::Vector3f>& last_scan_points() const { return last_scan_points_; }

 private:
  LidarOdometryConfig config_;
  cloud::VoxelHashMap map_;
  SE3 pose_;
  SE3 last_motion_;  ///< T_previous_current of the last scan
  std::optional<Timestamp> last_time_;
  double last_interval_ = 0.0;  ///< s between the last two scans
  std::size_t scans_ = 0;
  std::size_t degenerate_scans_ = 0;
  std::size_t weather_degraded_scans_ = 0;
  double average_returns_ = 0.0;  ///< running average of the returns in range of clear sweeps
  std::vector<Eigen::Vector3f> last_scan_points_;
};

}  // namespace hanzo::fusion::lidar
