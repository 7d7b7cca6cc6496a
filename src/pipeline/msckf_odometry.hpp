#pragma once
// MsckfOdometry: the Session's visual-inertial odometry (frontend.type: msckf): the KLT feature
// tracker and the MSCKF (vision/feature_tracker.hpp, vision/msckf.hpp) on the cameras and the IMU.
//
// IMU samples (body clock) are buffered; a frame first propagates the filter through the samples
// up to its body time (camera time + the filter's time offset), so images may arrive a little
// after the IMU samples that follow them. Before the filter starts, a frame starts it by static
// alignment (estimate/static_alignment.hpp) on the last second of IMU before it: roll, pitch and
// the gyro bias; heading 0; at rest. A platform moving at the start starts in motion from the
// visual-inertial alignment of camera 0's last 1.5 s of tracks with the IMU
// (vision/visual_inertial_alignment.hpp: velocity, gravity direction and gyro bias); when that
// fails (too little parallax, images and IMU disagreeing), from roll and pitch of the second's
// mean specific force (moving_start.hpp) and, with two cameras, the velocity from the last two
// stereo frames; without one, after 2 s more of failures, with zero velocity and a 1 m/s
// standard deviation for the images to correct.
// A filter whose covariance breaks down numerically is dropped and started again the same way.
//
// Several rigs (a rig: one camera or a stereo pair; two stereo pairs looking ahead and behind,
// for example): each rig has its own tracker, and one filter takes every rig's features (the
// MSCKF's cameras in rig order, feature ids made unique per rig). A frame holds the images the
// rigs took at one time (track()); a rig missing from a frame keeps its tracks open. The start
// (static or in motion) uses rig 0.
//
// World: gravity-aligned (z up), heading and origin those of the IMU at the start; poses are
// T_world_body (the IMU's pose moved by the calibration's imu_to_body).

#include <deque>
#include <map>
#include <memory>
#include <optional>

#include <opencv2/core.hpp>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/estimate/imu_propagation.hpp"
#include "hanzo/fusion/vision/feature_tracker.hpp"
#include "hanzo/fusion/vision/msckf.hpp"
#include "hanzo/fusion/vision/visual_inertial_alignment.hpp"

namespace hanzo::fusion::pipeline {

struct MsckfCameraSetup {
  PinholeCamera camera;
  SE3 T_body_camera;
};

/// A rig: one camera, or a stereo pair (left, right) of one image size.
struct MsckfRigSetup {
  std::vector<MsckfCameraSetup> cameras;
  cv::Size image_size;
};

class MsckfOdometry {
 public:
  struct Frame {
    bool tracking = false;  ///< false while initializing (the reason says why)
    SE3 T_world_body;
    vision::MsckfUpdateSummary update;
    std::string reason;
    int tracked_features = 0;  ///< left features continued from the previous image
    /// The trackers' observations of every rig in the frame: cameras numbered across the rigs
    /// (rig 0's first), feature ids unique across them (rig 0's as its tracker gives them).
    std::vector<vision::FeatureObservation> observations;
    double feature_seconds = 0.0;  ///< the trackers' time on this frame (detection and optical flow)
  };
  /// A rig's grey images of a frame (right empty for a single camera).
  struct RigImages {
    int rig = 0;
    cv::Mat left, right;
    vision::StaticMask static_mask;  ///< the left image's (FeatureTracker::track)
  };

  /// The rigs (one to four; each one or two cameras, the second making a stereo pair), the
  /// IMU's mounting and noise; fails as the trackers and the filter do on a bad calibration.
  static Result<std::unique_ptr<MsckfOdometry>> create(const std::vector<MsckfRigSetup>& rigs, const SE3& T_body_imu,
                                                       const estimate::ImuNoise& imu_noise, const vision::FeatureTrackerConfig& tracker = {});

  /// An IMU sample on the body clock, in time order (older or repeated samples are ignored).
  void add_imu(const estimate::ImuSample& sample);
  /// A frame at its body-clock time: the images of the rigs that took one then (each rig at
  /// most once). Fails for an unknown rig or images the rig's tracker refuses.
  Result<Frame> track(Timestamp time, const std::vector<RigImages>& images);
  /// A frame of rig 0 alone.
  Result<Frame> track(Timestamp time, const cv::Mat& left, const cv::Mat& right) { return track(time, {{0, left, right, {}}}); }

  int zero_velocity_frames() const { return zero_velocity_frames_; }
  /// The filter's IMU biases (IMU axes: accelerometer m/s^2, gyroscope rad/s); nullopt before it starts.
  std::optional<std::pair<Eigen::Vector3d, Eigen::Vector3d>> imu_bias() const;
  bool initialized() const { return filter_.has_value(); }

 private:
  struct Rig {
    std::unique_ptr<vision::FeatureTracker> tracker;
    int first_camera = 0;  // its left camera's index in cameras_
    bool stereo = false;
  };
  MsckfOdometry(std::vector<Rig> rigs, std::vector<vision::MsckfCamera> cameras, const SE3& T_body_imu, const estimate::ImuNoise& imu_noise);
  std::optional<std::string> start_filter(Timestamp time);
  std::optional<std::string> start_with(const estimate::NavigationState& state, const Eigen::Matrix<double, 15, 1>& sigma,
                                        const estimate::ImuSample& last_sample);
  // In motion: the alignment of the frames kept so far, or nullopt with `why`.
  std::optional<vision::VisualInertialAlignment> align_in_motion(Timestamp time, std::string& why);

  std::vector<Rig> rigs_;
  std::vector<vision::MsckfCamera> cameras_;  // T_imu_camera: the MSCKF's body is the IMU
  SE3 T_body_imu_;
  estimate::ImuNoise imu_noise_;
  std::optional<vision::Msckf> filter_;
  std::deque<estimate::ImuSample> imu_;  // not yet propagated (before the start: the last seconds)
  // Rig 0 stereo, before the start: the last frame's stereo points (body frame) and the velocity
  // they and the frame before gave (body frame), for a start in motion.
  std::optional<std::pair<Timestamp, std::map<uint64_t, Eigen::Vector3d>>> previous_stereo_;
  std::optional<Eigen::Vector3d> stereo_velocity_;
  // Before the start: the last frames' tracks for the visual-inertial alignment.
  std::deque<vision::AlignmentFrame> alignment_frames_;
  std::optional<Timestamp> aligning_since_;  // first alignment attempt
  int zero_velocity_frames_ = 0;
};

}  // namespace hanzo::fusion::pipeline
