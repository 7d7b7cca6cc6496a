#pragma once
// Camera-LiDAR extrinsic calibration from a checkerboard seen by both (spec, "extrinsic
// calibration procedures"): the LiDAR's pose in the camera's optical frame, T_camera_lidar, from
// the board's plane and its outer edges.
//
//   calib::CameraLidarCalibrationConfig config;
//   config.target = {8, 6, 0.10};                    // inner corners, square (m)
//   config.board_width = 1.1; config.board_height = 0.9;  // the board around the pattern (m)
//   auto calibrated = calib::calibrate_camera_lidar(images, intrinsics, distortion, scans, config);
//   // calibrated->T_camera_lidar, ->covariance, ->plane_rms_m, ->edge_rms_m, ->certified
//
// Recording: hold the board (or the rig) still at several poses, at least min_stations, with
// the board entirely in the camera's view and crossed by several LiDAR rings; turn it about its
// vertical and horizontal axes (the plane normals must point in different directions) and roll
// it (a diamond, so that the rings cross every edge). Nothing may stand between the sensors and
// the board's edges.
//
// Steps:
//  1. Camera: the board's corners in each image (OpenCV findChessboardCorners + cornerSubPix),
//     T_camera_board by solvePnP with the given intrinsics and distortion.
//  2. Static views: a scan is used when the images just before its first point and just after
//     its last show the board in the same place (mean corner motion <= max_corner_motion_px), so
//     neither the board nor the rig moved during the sweep; its board pose is the PnP of the
//     image nearest to the sweep's middle. Consecutive static scans whose board poses agree
//     (1 cm, 0.5 deg) form one station.
//  3. LiDAR board points: without an estimate, the points in the range of the board's distance
//     from the camera (+- max_sensor_offset) are split into planes (RANSAC) and connected patches;
//     the patch of the board's size is the board (a view with none or several is left out). With
//     an estimate (an initial guess, or the first solve), the points near the predicted board
//     (plane_gate off its plane, edge_margin outside its outline) refit by RANSAC.
//  4. Edge points: on each ring, the first and last board point (in azimuth); each is moved to
//     where its ray meets the fitted plane (removing range noise) and out by half the ring's point
//     spacing (a ring's last hit lies on average half a step inside the edge).
//  5. Solve (Gauss-Newton, Huber-weighted): every board point on the camera's board plane
//     (n_c . (T p) = d_c), every edge point on its nearest board edge within that plane (the
//     in-plane distance), each kind weighted by its own residual RMS. Without an initial guess
//     the start is the closed form from the planes: R from the normals (Kabsch, n_c = R n_l), t
//     from n_c . t = d_c - d_l and the board centres (Unnikrishnan & Hebert 2005, "Fast
//     extrinsic calibration of a laser rangefinder to a camera", sec. 3). The LiDAR points are
//     then selected again with the solution and solved again.
//  6. Covariance over (rho, phi) of T_camera_lidar (right perturbation, m and rad): a jackknife
//     over the stations (each left out once, solved again), so that it reflects how much the
//     stations disagree, not only point noise.
//
// Frames and units: the camera's optical frame (x right, y down, z forward), the LiDAR's frame
// as its points are given; metres, radians, pixels (OpenCV convention). The board's frame: origin
// at the first inner corner, x along a row of corners, y along a column, z into the board; the
// pattern is centred on the board.
// Timing: image and scan stamps on one clock; a scan's points at point_timestamps when given,
// else from its stamp to the next scan's.
// Fails, naming what is wrong: a bad config, intrinsics or target, images of a depth encoding,
// scans with no points, fewer than min_stations stations where both sensors saw the board (the
// message gives the counts of every reason a scan was left out), board normals within
// min_normal_spread_deg of each other (the rotation about them is unobservable).
// `certified` is false when a one-sigma bound exceeds max_position_sigma or
// max_rotation_sigma_deg, or the edges lie off the outline by more than max_edge_bias on average:
// the result is returned, and the caller must not use it unchecked.
#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/calib/camera_calibration.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"

namespace hanzo::fusion::calib {

struct CameraLidarCalibrationConfig {
  CheckerboardTarget target{8, 6, 0.10};
  /// The physical board (m) along the target's x (a row of corners) and y; 0: the pattern's own
  /// extent ((inner corners + 1) squares), a board cut along its outer squares.
  double board_width = 0.0;
  double board_height = 0.0;
  /// A guess of T_camera_lidar (a measured mounting, within about 10 deg and 20 cm); without one
  /// the board is found by its size (step 3).
  std::optional<SE3> initial_T_camera_lidar;
  double max_sensor_offset = 0.5;      ///< m: the LiDAR is at most this far from the camera (search without a guess)
  double max_corner_motion_px = 0.5;   ///< mean corner motion across a scan for it to be static
  double plane_inlier_threshold = 0.06;  ///< m from the RANSAC plane (3 x a LiDAR's ~2 cm range noise)
  double plane_gate = 0.15;            ///< m off the predicted plane (with an estimate)
  double edge_margin = 0.10;           ///< m outside the predicted outline (with an estimate)
  double board_size_tolerance = 0.25;  ///< relative: a patch's extent against the board's
  std::size_t min_board_points = 30;   ///< LiDAR points on the board for a view to count
  std::size_t min_stations = 4;
  double min_normal_spread_deg = 10.0;  ///< the board's normals must span this much
  double max_position_sigma = 0.01;     ///< m, one sigma on any axis for `certified`
  double max_rotation_sigma_deg = 0.2;  ///< deg, one sigma on any axis for `certified`
  /// m: the edge points' mean distance outside the outline for `certified` (a wrong board size
  /// shows as a bias; a symmetric one leaves the pose nearly unchanged, so nothing else shows it).
  double max_edge_bias = 0.02;

  Status validate() const;
};

/// One scan with the board in both sensors (a static scan); used ones are in the solve.
struct CameraLidarView {
  Timestamp scan_time;
  Timestamp image_time;         ///< the image whose board pose the view uses
  std::size_t station = 0;
  SE3 T_camera_board;
  std::size_t board_points = 0;  ///< LiDAR points on the board
  std::size_t edge_points = 0;   ///< of them on its edges (ring ends)
  double plane_rms_m = 0.0;      ///< LiDAR board points from the camera's plane (solution)
  double edge_rms_m = 0.0;       ///< edge points from the camera's board edges, in the plane (solution)
};

struct CameraLidarCalibrationResult {
  SE3 T_camera_lidar;
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Zero();
  double plane_rms_m = 0.0;
  double edge_rms_m = 0.0;
  double edge_bias_m = 0.0;  ///< mean edge residual, > 0 outside the outline
  /// The largest angle (deg) between two used board normals (refused under min_normal_spread_deg).
  double normal_spread_deg = 0.0;
  bool certified = false;
  std::string weakest;  ///< the least certain axis, e.g. "position z (camera frame) 0.012 m"
  std::string not_certified_reason;  ///< what to change, empty when certified
  std::size_t images = 0, images_with_board = 0;
  std::size_t scans = 0, scans_static = 0, scans_used = 0, stations = 0;
  /// Scans left out, by reason: the board not in both bracketing images or moving, no board in
  /// the LiDAR (none or several patches of its size), too few board points.
  std::size_t scans_board_moving = 0, scans_board_not_in_lidar = 0, scans_too_few_points = 0;
  std::vector<CameraLidarView> views;  ///< the used scans, in time order
};

/// The board in one image (step 1).
struct BoardObservation {
  Timestamp time;
  bool found = false;                     ///< every inner corner found and a pose solved
  std::vector<Eigen::Vector2f> corners;   ///< px, OpenCV's order (found boards)
  SE3 T_camera_board;                     ///< found boards
};

/// Step 1 on every image (in parallel), in the images' order. Fails on bad intrinsics or an image
/// that is not an intensity image.
Result<std::vector<BoardObservation>> observe_board(const std::vector<msgs::ImageMessage>& images, const msgs::CameraIntrinsics& intrinsics,
                                                    const msgs::DistortionModel& distortion, const CheckerboardTarget& target);

/// Steps 2-6 on boards observed in the images (observe_board, or another detector's poses).
Result<CameraLidarCalibrationResult> calibrate_camera_lidar(const std::vector<BoardObservation>& boards,
                                                            const std::vector<msgs::PointCloudMessage>& scans,
                                                            const CameraLidarCalibrationConfig& config);

/// observe_board, then calibrate_camera_lidar on its boards.
Result<CameraLidarCalibrationResult> calibrate_camera_lidar(const std::vector<msgs::ImageMessage>& images, const msgs::CameraIntrinsics& intrinsics,
                                                            const msgs::DistortionModel& distortion,
                                                            const std::vector<msgs::PointCloudMessage>& scans,
                                                            const CameraLidarCalibrationConfig& config);

/// The residual of a point on a line or plane of the camera frame, r = a . (T_camera_lidar p) - b
/// (m; a unit), and its Jacobian with respect to T_camera_lidar (right perturbation (rho, phi)):
/// what step 5 sums. Public for the test that checks it numerically.
double point_constraint_residual(const SE3& T_camera_lidar, const Eigen::Vector3d& point_lidar, const Eigen::Vector3d& direction_camera,
                                 double offset, Eigen::Matrix<double, 1, 6>* jacobian = nullptr);

}  // namespace hanzo::fusion::calib
