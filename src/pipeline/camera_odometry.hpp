#pragma once
// CameraOdometry: the Session's visual odometry (vision::VisualOdometry) on the configuration's
// cameras, and how its poses reach the Frontend.
//
// Cameras: the first camera sensor of the configuration with intrinsics in the calibration is
// the left (monocular) camera; a second camera with intrinsics of the same size makes it a
// stereo pair (the right image of a time completes the pair; a left image whose right one
// never comes, and a right without its left, are dropped). Images must be mono8, rgb8 or bgr8 of
// the calibrated size; the sensor's time offset moves them to the body clock.
//
// With frontend.type msckf and an IMU, the odometry is visual-inertial instead
// (msckf_odometry.hpp: KLT tracks and the MSCKF, metric with one camera too): the Session gives
// it the IMU's samples as well, and its body poses are fused the same way.
//
// Every left image's quality is assessed (vision/image_quality.hpp: dark, glare, motion blur) and
// counted. The visual-inertial odometry's frame is lost when its image is dark or fewer than
// kMinTrackedFeatures features continued from the previous image: the filter goes on with the
// IMU and what features it has, and tracking resumes by itself once the images are usable again.
//
// Fusion (Session): the odometry's camera poses are pose measurements (Frontend::push_pose).
// Without an IMU its world (the body frame at its first keyframe) is the Frontend's; with an
// IMU (stereo: metric) its world is placed once in the Frontend's, by the Frontend's pose at the
// first tracked frame, as the LiDAR odometry's map is. A monocular visual odometry with an IMU
// is tracked but not fused: its scale is unknown (the visual-inertial odometry, frontend.type
// msckf, is metric with one camera), and the counts say so (not_fused).

#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/vision/image_quality.hpp"
#include "hanzo/fusion/vision/visual_odometry.hpp"
#include "msckf_odometry.hpp"
#include "imu_keyframe_chain.hpp"
#include "visual_inertial_factors.hpp"

namespace hanzo::fusion::pipeline {

class CameraOdometry {
 public:
  /// A tracked image (pair): the body-clock time and the odometry's outcome, with the camera
  /// pose moved into the odometry's body world: T_world_body = T_body_left T_left0_left T_body_left^-1.
  struct Tracked {
    Timestamp time;
    vision::VisualOdometryFrame frame;
    SE3 T_world_body;
    vision::ImageQuality image_quality;  ///< the left image's
    cv::Mat left_image;                  ///< 8-bit grey (shared, not copied)
  };
  /// Left images by condition (good ones are not counted).
  struct ImageConditionCounts {
    uint64_t dark = 0;
    uint64_t glare = 0;
    uint64_t motion_blur = 0;
  };
  /// Visual-inertial frames with fewer features continued from the previous image are lost.
  static constexpr int kMinTrackedFeatures = 20;

  /// nullptr (no error) when the configuration has no camera with intrinsics. Fails for
  /// frontend.type msckf without an IMU sensor.
  static Result<std::unique_ptr<CameraOdometry>> create(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                        const vision::VisualOdometryConfig& odometry_config = {});

  bool handles(std::string_view sensor) const { return sensor == left_sensor_ || (stereo() && sensor == right_sensor_); }
  bool stereo() const { return !right_sensor_.empty(); }
  const std::string& left_sensor() const { return left_sensor_; }
  const std::string& right_sensor() const { return right_sensor_; }
  const SE3& T_body_left() const { return T_body_left_; }
  const PinholeCamera& left_camera() const { return left_camera_; }
  /// The left camera's calibrated time offset (t_body = t_camera + offset).
  Duration left_time_offset() const { return left_offset_; }
  Duration right_time_offset() const { return right_offset_; }

  /// Takes an image of a handled sensor. Returns the tracked frame when an image (pair)
  /// completed; nullopt while a stereo pair waits for its other half. Fails (naming the
  /// problem) for an image of the wrong encoding or size, or out of time order.
  Result<std::optional<Tracked>> add(std::string_view sensor, const msgs::ImageMessage& image);

  /// Visual-inertial (frontend.type msckf): the odometry wants the IMU's samples (add_imu()).
  bool visual_inertial() const { return inertial_ != nullptr; }
  const std::string& imu_sensor() const { return imu_sensor_; }
  /// An IMU message of imu_sensor() (sensor clock; the calibrated offset is applied here).
  void add_imu(const msgs::ImuMessage& imu);
  /// Visual-inertial: the keyframe graph's IMU and landmark factors, fed with the IMU samples
  /// (body axes, body clock) and the tracked frames' features (null otherwise).
  VisualInertialFactors* keyframe_factors() { return keyframe_factors_.get(); }
  /// Visual-inertial: the filter's IMU biases in body axes (nullopt before it starts).
  std::optional<graph::ImuBias> imu_bias_body() const;

  vision::VisualOdometrySummary summary() const;
  const ImageConditionCounts& image_conditions() const { return image_conditions_; }
  /// The odometry's landmark map (its world: the left camera at its first keyframe).
  /// (Empty for the visual-inertial odometry: it keeps no landmarks.)
  msgs::VisualLandmarkLayer landmark_layer() const { return odometry_ ? odometry_->landmark_layer(left_sensor_) : msgs::VisualLandmarkLayer{}; }

 private:
  CameraOdometry(std::unique_ptr<vision::VisualOdometry> odometry, std::string left_sensor, std::string right_sensor, const PinholeCamera& left_camera,
                 const SE3& T_body_left, Duration left_offset, Duration right_offset);
  static Result<std::unique_ptr<CameraOdometry>> create_visual_inertial(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                                        const std::vector<const calib::SensorCalibration*>& cameras, bool stereo_pair,
                                                                        cv::Size size);
  Result<std::optional<Tracked>> track(Timestamp time, const cv::Mat& left, const cv::Mat& right);

  std::unique_ptr<vision::VisualOdometry> odometry_;  // null when visual-inertial
  std::unique_ptr<MsckfOdometry> inertial_;
  std::unique_ptr<VisualInertialFactors> keyframe_factors_;
  SE3 T_body_imu_;
  std::optional<BodyImu> body_imu_;  // the IMU's samples as the body origin's motion (keyframe factors)
  std::string imu_sensor_;
  Duration imu_offset_;
  vision::VisualOdometrySummary inertial_summary_;
  std::string left_sensor_, right_sensor_;
  PinholeCamera left_camera_;
  SE3 T_body_left_;
  Duration left_offset_, right_offset_;
  std::optional<std::pair<Timestamp, cv::Mat>> waiting_left_;  // stereo: a left image waiting for its right
  vision::ImageQualityMonitor image_quality_ = vision::ImageQualityMonitor::create().value();
  ImageConditionCounts image_conditions_;
};

}  // namespace hanzo::fusion::pipeline
