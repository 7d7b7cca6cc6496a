#pragma once
// CameraOdometry: the Session's visual odometry (vision::VisualOdometry) on the configuration's
// cameras, and how its poses reach the Frontend.
//
// Cameras: the camera sensors of the configuration with intrinsics in the calibration, in the
// configuration's order, form rigs: a camera and the next one of the same image size are a
// stereo pair (left, right), or an RGB-D camera when the next one is of type depth
// (config::kDepthCameraType: its depth images registered to the camera), a camera without one is
// a rig of its own. Rig 0's left camera is
// "the left camera". Images must be mono8, rgb8 or bgr8 of the calibrated size; the sensor's
// time offset moves them to the body clock. The images of one time (within 1 ms) make a frame,
// tracked once every rig's image(s) of that time came, or when an image of a later time comes
// (the rigs complete by then; a stereo half without its other half is dropped). An RGB-D rig's
// images are paired with its depth images the same way; the visual odometry is then metric
// (vision::VisualOdometry::create_rgbd) and fused as stereo's is; the visual-inertial odometry
// tracks its camera alone.
//
// With frontend.type msckf and an IMU, the odometry is visual-inertial (msckf_odometry.hpp: KLT
// tracks and the MSCKF, metric with one camera too) on every rig (two stereo pairs looking
// ahead and behind, say): the Session gives it the IMU's samples as well, and its body poses
// are fused the same way. The visual odometry of the other frontends takes rig 0 alone (the
// other cameras are reported as not used).
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
#include <vector>

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
  /// A tracked frame: the body-clock time and the odometry's outcome, with the camera pose
  /// moved into the odometry's body world: T_world_body = T_body_left T_left0_left T_body_left^-1.
  struct Tracked {
    Timestamp time;
    vision::VisualOdometryFrame frame;
    SE3 T_world_body;
    vision::ImageQuality image_quality;  ///< the best of the frame's left images
    /// The left image of each rig in the frame (rig index, 8-bit grey; shared, not copied).
    std::vector<std::pair<int, cv::Mat>> left_images;
    std::vector<vision::StaticMask> left_masks;  ///< each left image's moving objects (left_images' order)
    std::vector<std::string> sensors;    ///< the cameras whose images made the frame
  };
  /// A camera rig: one camera, or a stereo pair.
  struct Rig {
    std::string left_sensor, right_sensor;  ///< right empty for one camera
    Duration left_offset, right_offset;     ///< calibrated time offsets (t_body = t_camera + offset)
    cv::Size image_size;
    PinholeCamera left_camera;
    SE3 T_body_left;
    bool depth = false;  ///< the right sensor is the left camera's depth images (an RGB-D camera)
    bool stereo() const { return !right_sensor.empty() && !depth; }
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

  bool handles(std::string_view sensor) const { return rig_of(sensor) != nullptr; }
  /// The rigs the odometry tracks (rig 0 first).
  const std::vector<Rig>& rigs() const { return rigs_; }
  /// The rig a camera belongs to (null for a camera the odometry does not take).
  const Rig* rig_of(std::string_view sensor) const;
  bool stereo() const { return rigs_[0].stereo(); }
  /// Rig 0 gives metric poses by itself: a stereo pair or an RGB-D camera.
  bool metric() const { return !rigs_[0].right_sensor.empty(); }
  const std::string& left_sensor() const { return rigs_[0].left_sensor; }
  const std::string& right_sensor() const { return rigs_[0].right_sensor; }
  const SE3& T_body_left() const { return rigs_[0].T_body_left; }
  /// The left camera's calibrated time offset (t_body = t_camera + offset).
  Duration left_time_offset() const { return rigs_[0].left_offset; }

  /// Takes an image of a handled sensor. Returns the tracked frame when a frame completed
  /// (header comment); nullopt while it waits for the rest of its images. Fails (naming the
  /// problem) for an image of the wrong encoding or size, or out of time order.
  /// static_mask (a left image's, optional): its moving objects, where no feature is taken (vision::VisualOdometry::track; the visual-inertial
  /// odometry's tracker drops its tracks there and detects no corners there).
  Result<std::optional<Tracked>> add(std::string_view sensor, const msgs::ImageMessage& image, const vision::StaticMask& static_mask = {});

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
  msgs::VisualLandmarkLayer landmark_layer() const { return odometry_ ? odometry_->landmark_layer(left_sensor()) : msgs::VisualLandmarkLayer{}; }
  /// The visual odometry's keypoint extractor (the configuration's features; null for the
  /// visual-inertial odometry, which tracks KLT corners).
  const std::shared_ptr<const vision::FeatureExtractor>& extractor() const { return extractor_; }

 private:
  // The images of one time, by rig (empty until they come).
  struct PendingFrame {
    Timestamp time;                      // its first image's
    std::optional<Timestamp> left_time;  // the frame's time: rig 0's left image's, else the first left image's
    std::vector<std::pair<cv::Mat, cv::Mat>> images;
    std::vector<vision::StaticMask> static_masks;  // by rig: the left image's
  };

  CameraOdometry(std::unique_ptr<vision::VisualOdometry> odometry, std::vector<Rig> rigs);
  static Result<std::unique_ptr<CameraOdometry>> create_visual_inertial(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                                        const std::vector<std::vector<const calib::SensorCalibration*>>& rigs);
  // Tracks the pending frame's complete rigs (nullopt when none is).
  Result<std::optional<Tracked>> track_pending();
  Result<Tracked> track_inertial(Timestamp time, const std::vector<MsckfOdometry::RigImages>& images);
  // A left image's quality, counted by condition.
  Result<vision::ImageQuality> assess(const cv::Mat& left);

  std::unique_ptr<vision::VisualOdometry> odometry_;  // null when visual-inertial
  std::shared_ptr<const vision::FeatureExtractor> extractor_;  // the odometry's (null when visual-inertial)
  std::unique_ptr<MsckfOdometry> inertial_;
  std::unique_ptr<VisualInertialFactors> keyframe_factors_;
  SE3 T_body_imu_;
  std::optional<BodyImu> body_imu_;  // the IMU's samples as the body origin's motion (keyframe factors)
  std::string imu_sensor_;
  Duration imu_offset_;
  vision::VisualOdometrySummary inertial_summary_;
  std::vector<Rig> rigs_;
  std::optional<PendingFrame> pending_;
  vision::ImageQualityMonitor image_quality_ = vision::ImageQualityMonitor::create().value();
  ImageConditionCounts image_conditions_;
};

}  // namespace hanzo::fusion::pipeline
