#pragma once
// Msckf: the Multi-State Constraint Kalman Filter (Mourikis and Roumeliotis 2007, "A
// Multi-State Constraint Kalman Filter for Vision-aided Inertial Navigation"), the core of
// visual-inertial odometry: an error-state EKF over the IMU state and a sliding window of cloned
// body poses, updated by feature tracks without keeping the features in the state.
//
// State: the IMU's NavigationState (estimate/navigation_state.hpp) and a sliding window of cloned
// body poses. Gravity is fixed at the initial state's (its direction from the initialization); the
// wheel and gyro-scale entries of NavigationState are not used.
//
// Error state (the covariance's coordinates): the right-invariant error of the IMU's extended pose
// and of each clone (Barrau and Bonnabel 2017, "The Invariant Extended Kalman Filter as a Stable
// Observer"; its use in an MSCKF: Heo and Park 2018, "Consistent EKF-Based Visual-Inertial
// Odometry on Matrix Lie Group"), in world coordinates:
//   R = Exp(phi) R_est,  v = Exp(phi) v_est + xi_v,  p = Exp(phi) p_est + xi_p
//   IMU    15: xi_p (0), phi (3), xi_v (6), dba (9), dbg (12)   (biases additive)
//   clones 6 each, oldest first: xi_p, phi of T_world_body at a camera time.
// The directions the cameras and the IMU cannot observe (a rotation of everything about gravity,
// a translation of everything) are then the same vectors at every estimate, so the propagation
// and the feature Jacobians keep them unobservable wherever they are linearized: the consistency
// first-estimate Jacobians (Li and Mourikis 2013) buy, without holding Jacobians at old
// estimates. covariance() and imu_covariance() convert to the body-frame error of
// NavigationState (dp, dtheta with R = R_est Exp(dtheta), dv, dba, dbg) that the rest of the
// library uses: dp = xi_p - [p]x phi, dtheta = R^T phi, dv = xi_v - [v]x phi.
//
// Per camera frame (process_frame):
//   1. the IMU state is propagated to the frame time (estimate/imu_propagation.hpp; the IMU
//      transition and noise of the samples since the last frame are applied to the covariance
//      at once) and its pose cloned: P <- [P, P J^T; J P, J P J^T] with J selecting (xi_p, phi);
//   2. the features to use are those whose track ended (not observed in this frame by a rig
//      the frame images) and, when the window is full, those observed by the oldest clone; each
//      needs two observations;
//   3. each feature is triangulated from its observations (linear multi-view least squares,
//      then Gauss-Newton on the reprojection errors) with the clone poses; a feature behind a
//      camera, nearer than min_depth or farther than max_depth, seen over less than
//      min_parallax_deg, or badly conditioned is dropped;
//   4. its whitened residuals r = H_c dx + H_f dp_f + n (2 rows per observation, normalized image
//      coordinates over their noise) are projected onto the left null space N of H_f (from its
//      Householder QR, H_f = [Q1 N] [R; 0]): r0 = N^T r = N^T H_c dx + N^T n (eq. 23-24 of the
//      paper), removing the feature's error;
//   5. a feature whose r0^T (N^T (H_c P H_c^T + I) N)^-1 r0 exceeds the chi-square quantile
//      (chi_square_probability, 2m - 3 degrees of freedom) is dropped as an outlier (H_c P H_c^T
//      is built from the 6 x 6 covariance blocks of the clones the feature was seen in);
//   6. the accepted features are summed as information over the clone states,
//      J = sum H0^T H0 = sum H_c^T (I - Q1 Q1^T) H_c and g = sum H0^T r0: the same update as the
//      paper's QR compression of the stacked rows (eq. 26-28) at a fraction of its cost. With
//      P = F F^T (pivoted LDLT; P is singular right after a clone is added):
//      P <- F (I + F^T J F)^-1 F^T, dx = F (I + F^T J F)^-1 F^T g, then x <- x (+) dx;
//   7. the used observations are deleted, and when the window holds more than max_clones clones
//      the oldest is marginalized (its rows and columns removed).

// Frames: world is the frame of the initial state (z up for gravity (0, 0, -g)); body as the
// NavigationState; cameras at T_body_camera (x right, y down, z forward). Observations are
// UNDISTORTED normalized coordinates (x/z, y/z) of the camera (PinholeCamera::unproject).
//
// Rigs: cameras that image together (a stereo pair) form a rig (MsckfCamera::rig). A frame holds
// the images of one or more rigs taken at one time; several rigs imaged at one time are one
// frame (one clone), and a rig whose image is not in a frame keeps its tracks open. The
// zero-velocity test looks at camera 0, in frames that image its rig.
//
// Failures: process_frame() refuses a time before the last one, an unknown camera index, a
// feature observed twice by one camera or a non-finite observation (the frame is skipped, the state unchanged); propagate() refuses a
// sample older than the state or non-finite. A filter whose covariance stops being finite
// (numerical breakdown) refuses further frames: reset it from an initialization.

#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"
#include "hanzo/fusion/estimate/navigation_state.hpp"
#include "hanzo/fusion/vision/feature_observation.hpp"

namespace hanzo::fusion::vision {

inline constexpr int kMsckfImuDimension = 15;
inline constexpr int kMsckfCloneDimension = 6;
/// Cameras one filter takes (four stereo pairs).
inline constexpr int kMsckfMaxCameras = 8;

struct MsckfConfig {
  /// Clones in the sliding window (OpenVINS's default 11: about 0.5-1 s of a 10-20 Hz camera).
  int max_clones = 11;
  /// Feature position noise, pixels (turned into normalized units by each camera's focal length).
  /// 2 px for the KLT tracker (feature_tracker.hpp) on real images: its errors are larger and
  /// less regular than 1 px of white noise (JPEG, blur, people walking through). With 1 px of
  /// simulated white noise, pixel_sigma = 1 is consistent (tests/vision/msckf_test.cpp).
  double pixel_sigma = 2.0;
  /// Probability of the chi-square gate per feature (0.95: OpenVINS's).
  double chi_square_probability = 0.95;
  /// Triangulated features nearer or farther than this (metres, in every observing camera) are
  /// dropped: too near is a tracking error, too far carries no translation information.
  double min_depth = 0.1;
  double max_depth = 60.0;
  /// A feature whose viewing rays are never this far apart (degrees) is not used: its depth is
  /// mostly noise, and a wrong depth turns rotation information into false translation
  /// information (a camera standing still would otherwise grow overconfident).
  double min_parallax_deg = 2.0;
  /// Gauss-Newton iterations of the feature triangulation.
  int triangulation_iterations = 8;
  /// IMU noise (estimate/imu_propagation.hpp's model and units).
  estimate::ImuNoise imu_noise;
  /// Online calibration by state augmentation (as OpenVINS): each camera's T_body_camera and the
  /// rig's time offset (t_body = t_camera + time_offset) are estimated, starting from the values
  /// given at creation with these standard deviations as their prior.
  bool calibrate_extrinsics = true;
  double extrinsic_rotation_sigma = 0.1;      ///< rad
  double extrinsic_translation_sigma = 0.05;  ///< m
  bool calibrate_time_offset = true;
  double time_offset_sigma = 0.02;            ///< s
  /// Zero-velocity update (as OpenVINS's): when the features of camera 0 moved less than
  /// zero_velocity_max_disparity_px beyond their noise (median over at least 10 features, each
  /// against its position in the last frame that was cloned, so that a slow creep adds up;
  /// the noise's share is the median displacement of a still feature with pixel_sigma), the frame
  /// is not cloned (standing still gives no parallax) and the velocity is updated to zero with
  /// zero_velocity_sigma instead, unless that measurement fails the chi-square gate (a creep the
  /// features cannot see yet).
  bool zero_velocity_update = true;
  double zero_velocity_max_disparity_px = 0.5;
  double zero_velocity_sigma = 0.01;          ///< m/s
};

/// Checks every field; the error names the first field out of range.
Status validate(const MsckfConfig& config);

/// A camera of the rig: where it sits on the body, and its focal length (pixels) to turn
/// pixel_sigma into normalized units.
struct MsckfCamera {
  SE3 T_body_camera;
  double focal_length_px = 500.0;
  int rig = 0;  ///< cameras that image together share a rig number (header comment)
};

/// The outcome of one frame's update.
struct MsckfUpdateSummary {
  int features_offered = 0;          ///< features whose tracks were used or tried
  int features_used = 0;             ///< passed triangulation and the chi-square gate
  int rejected_triangulation = 0;    ///< behind / too near / too far / ill-conditioned
  int rejected_chi_square = 0;       ///< outliers by the gate
  int residual_rows = 0;             ///< rows of the stacked update after null-space projection
  int clones = 0;                    ///< clones in the window after the frame
  bool zero_velocity = false;        ///< standing still: updated to zero velocity, not cloned
};

/// A cloned body pose in the window.
struct MsckfClone {
  Timestamp timestamp;  ///< the frame's camera time
  SE3 T_world_body;     ///< at the frame's body time (camera time + time offset)
};

class Msckf {
 public:
  /// Fails when the configuration is out of range, no or more than kMsckfMaxCameras cameras are given, a
  /// focal length is not positive, the state is not finite or the covariance is not a finite
  /// symmetric 15 x 15 matrix with a positive diagonal (IMU error order above).
  /// time_offset: the cameras' clock against the body's (t_body = t_camera + time_offset),
  /// calibrated online when the configuration says so, as are the cameras' T_body_camera.
  static Result<Msckf> create(const MsckfConfig& config, const std::vector<MsckfCamera>& cameras,
                              const estimate::NavigationState& initial_state, const Eigen::MatrixXd& initial_covariance,
                              Duration time_offset = {});

  /// Integrates the IMU state to the sample's time with the mean of the previous and this
  /// sample's readings held over the interval (the first sample is held back to the state time).
  Status propagate(const estimate::ImuSample& sample);

  /// Clones the pose at the frame's body time (`time`, the cameras' clock, plus time_offset();
  /// propagated from the last IMU sample, held) and updates with the tracks this frame ends
  /// (header comment). The observations are this frame's, every camera; `rigs` the rigs whose
  /// images made the frame (empty: every rig). Feed the IMU samples up to body_time(time)
  /// first, and no later ones.
  Result<MsckfUpdateSummary> process_frame(Timestamp time, const std::vector<FeatureObservation>& observations,
                                           const std::vector<int>& rigs = {});
  /// The body time of a camera time with the current time-offset estimate.
  Timestamp body_time(Timestamp camera_time) const { return camera_time + Duration::from_seconds(time_offset_); }

  const estimate::NavigationState& state() const { return state_; }
  /// The full error covariance at the last frame in NavigationState's body-frame error (header
  /// comment): IMU (15), time offset (1, when calibrated), extrinsics (6 per camera, when
  /// calibrated), clones (dp, dtheta each).
  Eigen::MatrixXd covariance() const;
  /// The IMU state's error covariance now (propagated through the samples since the last frame).
  Eigen::Matrix<double, kMsckfImuDimension, kMsckfImuDimension> imu_covariance() const;
  const std::deque<MsckfClone>& clones() const { return clones_; }
  /// The cameras with their current (calibrated) T_body_camera, and the time offset (seconds).
  const std::vector<MsckfCamera>& cameras() const { return cameras_; }
  double time_offset() const { return time_offset_; }
  /// True once the covariance stopped being finite: the filter refuses frames from then on.
  bool diverged() const { return diverged_; }
  /// Features with observations waiting for their track to end.
  int pending_features() const { return static_cast<int>(tracks_.size()); }

 private:
  struct TrackObservation {
    Timestamp clone_time;
    int camera = 0;
    Eigen::Vector2d normalized;
  };

  Msckf(const MsckfConfig& config, std::vector<MsckfCamera> cameras, const estimate::NavigationState& state,
        const Eigen::MatrixXd& imu_covariance, double time_offset);
  // Error-state layout: IMU (15), time offset (1, when calibrated), extrinsics (6 per camera, when
  // calibrated), clones (6 each).
  Eigen::Index time_offset_index() const { return kMsckfImuDimension; }
  Eigen::Index extrinsic_index(int camera) const { return kMsckfImuDimension + (config_.calibrate_time_offset ? 1 : 0) + 6 * camera; }
  Eigen::Index clone_index(size_t clone) const { return first_clone_ + kMsckfCloneDimension * static_cast<Eigen::Index>(clone); }
  using ImuMatrix = Eigen::Matrix<double, kMsckfImuDimension, kMsckfImuDimension>;
  void propagate_interval(const estimate::ImuSample& reading, double dt);
  // The body-frame error of the whole state from the invariant one: dx = T xi (header comment).
  Eigen::MatrixXd body_error_from_invariant() const;
  void apply_interval_propagation();
  void augment(Timestamp time);
  void marginalize_oldest_clone();
  MsckfUpdateSummary update(const std::vector<uint64_t>& feature_ids);
  void apply_correction(const Eigen::VectorXd& correction);
  bool standing_still(const std::vector<FeatureObservation>& observations) const;
  bool update_zero_velocity();

  MsckfConfig config_;
  std::vector<MsckfCamera> cameras_;
  estimate::NavigationState state_;
  Eigen::MatrixXd covariance_;  // invariant error (header comment)
  std::deque<MsckfClone> clones_;
  double time_offset_ = 0.0;
  Eigen::Index first_clone_ = kMsckfImuDimension;
  std::map<uint64_t, std::vector<TrackObservation>> tracks_;
  std::optional<estimate::ImuSample> last_sample_;
  std::optional<Timestamp> last_frame_time_;
  std::map<uint64_t, Eigen::Vector2d> standing_reference_;  // camera 0's in the last cloned frame, by feature id
  // The IMU transition and noise accumulated since the last frame (body-frame error, from the
  // state at the interval's start to the state now), applied to the covariance at the next frame
  // (one product with the clone columns per frame instead of per IMU sample).
  ImuMatrix interval_transition_ = ImuMatrix::Identity();
  ImuMatrix interval_noise_ = ImuMatrix::Zero();
  estimate::NavigationState interval_start_;
  bool interval_empty_ = true;
  bool diverged_ = false;
};

}  // namespace hanzo::fusion::vision
