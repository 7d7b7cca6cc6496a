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

class MsckfOdometry {
 public:
  struct Frame {
    bool tracking = false;  ///< false while initializing (the reason says why)
    SE3 T_world_body;
    vision::MsckfUpdateSummary update;
    std::string reason;
    int tracked_features = 0;  ///< left features continued from the previous image
    std::vector<vision::FeatureObservation> observations;  ///< the tracker's, both cameras
    double feature_seconds = 0.0;  ///< the tracker's time on this frame (detection and optical flow)
  };

  /// One or two cameras (the second makes a stereo rig), the IMU's mounting and noise; fails
  /// as the tracker and the filter do on a bad calibration.
  static Result<std::unique_ptr<MsckfOdometry>> create(const std::vector<MsckfCameraSetup>& cameras, cv::Size image_size, const SE3& T_body_imu,
                                                       const estimate::ImuNoise& imu_noise, const vision::FeatureTrackerConfig& tracker = {});

  /// An IMU sample on the body clock, in time order (older or repeated samples are ignored).
  void add_imu(const estimate::ImuSample& sample);
  /// A frame (grey images; right empty for a single camera) at its body-clock time.
  Result<Frame> track(Timestamp time, const cv::Mat& left, const cv::Mat& right);

  int zero_velocity_frames() const { return zero_velocity_frames_; }
  /// The filter's IMU biases (IMU axes: accelerometer m/s^2, gyroscope rad/s); nullopt before it starts.
  std::optional<std::pair<Eigen::Vector3d, Eigen::Vector3d>> imu_bias() const;
  bool initialized() const { return filter_.has_value(); }

 private:
  MsckfOdometry(std::unique_ptr<vision::FeatureTracker> tracker, std::vector<vision::MsckfCamera> cameras, const SE3& T_body_imu,
                const estimate::ImuNoise& imu_noise);
  std::optional<std::string> start_filter(Timestamp time);
  std::optional<std::string> start_with(const estimate::NavigationState& state, const Eigen::Matrix<double, 15, 1>& sigma,
                                        const estimate::ImuSample& last_sample);
  // In motion: the alignment of the frames kept so far, or nullopt with `why`.
  std::optional<vision::VisualInertialAlignment> align_in_motion(Timestamp time, std::string& why);

  std::unique_ptr<vision::FeatureTracker> tracker_;
  std::vector<vision::MsckfCamera> cameras_;  // T_imu_camera: the MSCKF's body is the IMU
  SE3 T_body_imu_;
  estimate::ImuNoise imu_noise_;
  std::optional<vision::Msckf> filter_;
  std::deque<estimate::ImuSample> imu_;  // not yet propagated (before the start: the last seconds)
  // Stereo, before the start: the last frame's stereo points (body frame) and the velocity
  // they and the frame before gave (body frame), for a start in motion.
  std::optional<std::pair<Timestamp, std::map<uint64_t, Eigen::Vector3d>>> previous_stereo_;
  std::optional<Eigen::Vector3d> stereo_velocity_;
  // Before the start: the last frames' tracks for the visual-inertial alignment.
  std::deque<vision::AlignmentFrame> alignment_frames_;
  std::optional<Timestamp> aligning_since_;  // first alignment attempt
  int zero_velocity_frames_ = 0;
};

}  // namespace hanzo::fusion::pipeline
