#pragma once
// Visual-inertial alignment: the state a visual-inertial filter starts from when the IMU is
// never still (a start in motion) and one camera cannot measure the velocity: gravity, velocity,
// gyro bias and the metric scale solved together from the first second or two of camera tracks
// and IMU samples (Qin, Li and Shen, "VINS-Mono", IEEE T-RO 34(4), 2018, section V):
//
//   1. Up-to-scale structure from motion of the window's frames: the essential matrix between
//      the first frame and the last frame still sharing min_tracks features (RANSAC), points
//      triangulated from the two, every frame placed by PnP on them, then the points
//      re-triangulated from all their views and the frames placed again.
//   2. Gyro bias: the IMU's preintegrated rotations (graph/imu_preintegration.hpp) against the
//      visual ones, min sum |Log(dR_ij(bg)^T R_bi^T R_bj)|^2 by Gauss-Newton on the bias
//      Jacobian (VINS-Mono eq. 15); the IMU re-preintegrated with it.
//   3. Velocities (each frame's, in the first camera's frame c0), gravity in c0 and the scale s
//      from the preintegrated position and velocity deltas (eq. 17-18), all linear:
//        s p_{k+1} - s p_k - (R_{k+1} - R_k) t_bc = v_k dt + 1/2 g dt^2 + R_k alpha_k
//        v_{k+1} = v_k + g dt + R_k beta_k
//      (p_k the camera's position and R_k the IMU's orientation in c0, t_bc the camera's
//      position in the IMU frame), least squares.
//   4. Gravity refined on its sphere |g| = gravity_magnitude (two tangent unknowns instead of
//      three, re-solved three times, eq. 19).
//
// Frames: the IMU (body of the filter) frame; observations are camera 0's undistorted normalized
// coordinates; T_imu_camera its mounting. The result is at the last frame: R_world_imu with
// world z up (gravity along -z) and yaw that of c0 (arbitrary), velocity in that world.
// Failure (an Error naming it): fewer than min_frames frames or IMU samples not covering them,
// too little parallax or too few tracks for the structure, a scale that is not positive, a
// gravity magnitude off by more than max_gravity_error before refinement (the vision and the
// IMU disagree: wrong extrinsics, a rolling shutter, dynamic scenes), or a non-finite solution.
// The accelerometer bias is not solved (it is indistinguishable from gravity over a second).

#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"
#include "hanzo/fusion/vision/feature_observation.hpp"

namespace hanzo::fusion::vision {

struct AlignmentFrame {
  Timestamp time;  ///< IMU clock
  std::vector<FeatureObservation> observations;  ///< camera 0's are used
};

struct VisualInertialAlignmentConfig {
  int min_frames = 8;
  int min_tracks = 30;                 ///< features the two structure frames share
  double min_parallax_degrees = 3.0;   ///< median angle between the two frames' rays (rotation removed)
  double focal_length_px = 450.0;      ///< camera 0's, to express pixel thresholds
  double ransac_threshold_px = 1.5;
  double gravity_magnitude = 9.80665;  ///< m/s^2
  double max_gravity_error = 0.1;      ///< fraction of gravity_magnitude
  double process_noise_accel = 0.1;    ///< the preintegration's noise (as ImuPreintegrationConfig)
  double process_noise_gyro = 0.01;
  double sample_interval = 0.005;      ///< s, 1 / IMU rate
};

struct VisualInertialAlignment {
  SO3 R_world_imu;                                        ///< at the last frame
  Eigen::Vector3d velocity_world = Eigen::Vector3d::Zero();  ///< m/s, at the last frame
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();     ///< rad/s
  double scale = 0.0;           ///< metres per unit of the structure (its first baseline = 1)
  double gravity_error = 0.0;   ///< | |g| / gravity_magnitude - 1 | before refinement
  int frames = 0;
  int points = 0;
};

/// Aligns the window `frames` (time order) with the IMU samples covering them (time order;
/// samples are held until the next one, as ImuPropagation does).
Result<VisualInertialAlignment> align_visual_inertial(const std::vector<AlignmentFrame>& frames, const std::vector<estimate::ImuSample>& imu,
                                                      const SE3& T_imu_camera, const VisualInertialAlignmentConfig& config = {});

}  // namespace hanzo::fusion::vision
