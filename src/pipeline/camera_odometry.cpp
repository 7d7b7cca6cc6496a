#include "camera_odometry.hpp"

#include <algorithm>

#include <fmt/format.h>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/pipeline/feature_extractors.hpp"
#include "hanzo/fusion/vision/image_message.hpp"

namespace hanzo::fusion::pipeline {
namespace {

// A learned detector offers the visual-inertial tracker this many candidates per feature it keeps
// (the grid then spreads them).
constexpr int kTrackerCandidates = 4;

// The features the cameras are configured with (fusion.vision.features or the left camera's own)
// and the configuration key they come from; a stereo pair's cameras must agree.
Result<std::pair<config::FeatureSelection, std::string>> configured_features(const config::FusionConfig& config, const std::string& left,
                                                                            const std::string& right) {
  // The cameras are sensors of the configuration.
  const config::SensorConfig& left_sensor = *config.find_sensor(left);
  const config::FeatureSelection& features = config.features_of(left_sensor);
  if (!right.empty()) {
    const config::FeatureSelection& right_features = config.features_of(*config.find_sensor(right));
    if (!(right_features == features)) {
      return Error(fmt::format("sensors.{}.features: {} differs from {}'s {} (a stereo pair matches one kind of descriptor)", right,
                               right_features.type, left, features.type),
                   fmt::format("sensors.{}.features", right));
    }
  }
  return std::pair{features, left_sensor.features ? fmt::format("sensors.{}.features", left) : std::string("vision.features")};
}

// vision.place_recognition (and place_model) for the extractor's descriptors: bags of words for
// ORB's (null), a VLAD model for learned ones. Unset, each gets its own kind; a learned model
// that cannot be found then gives null with a warning (no loop closure), as an optional stage.
Result<std::shared_ptr<const vision::VladModel>> place_model_for(const config::VisionConfig& vision, const vision::FeatureExtractor& extractor) {
  const bool learned_descriptors = extractor.descriptor_type() != CV_8UC1;
  const config::PlaceRecognitionType type =
      vision.place_recognition.value_or(learned_descriptors ? config::PlaceRecognitionType::kLearned : config::PlaceRecognitionType::kBow);
  if (type == config::PlaceRecognitionType::kBow) {
    if (learned_descriptors) {
      return Error(fmt::format("vision.place_recognition bow: the bag of words is of ORB descriptors, {} gives float ones (use learned)", extractor.name()),
                   "vision.place_recognition");
    }
    return std::shared_ptr<const vision::VladModel>();
  }
  if (!learned_descriptors) {
    return Error("vision.place_recognition learned: VLAD aggregates learned descriptors; vision.features is orb (choose a learned model)",
                 "vision.place_recognition");
  }
  Result<vision::VladModel> model = vision.place_model.empty() ? vision::VladModel::load_default(extractor.name()) : vision::VladModel::load(vision.place_model);
  if (!model && !vision.place_recognition && vision.place_model.empty()) {
    logger()->warn("vision.place_recognition: {}; the visual odometry closes no loops", model.error().message);
    return std::shared_ptr<const vision::VladModel>();
  }
  if (!model) return Error("vision.place_model: " + model.error().message, "vision.place_model");
  return std::shared_ptr<const vision::VladModel>(std::make_shared<const vision::VladModel>(std::move(model).value()));
}

// The configured features and matcher into the visual odometry's configuration.
Status apply_vision_config(const config::FusionConfig& config, const std::string& left, const std::string& right,
                           vision::VisualOdometryConfig& odometry) {
  if (!odometry.extractor) {
    std::pair<config::FeatureSelection, std::string> features;
    HANZO_ASSIGN_OR_RETURN(features, configured_features(config, left, right));
    HANZO_ASSIGN_OR_RETURN(odometry.extractor, make_feature_extractor(features.first, odometry.features.max_features, features.second, odometry.features));
  }
  if (odometry.loop_closure && !odometry.place_model) HANZO_ASSIGN_OR_RETURN(odometry.place_model, place_model_for(config.vision, *odometry.extractor));
  if (config.vision.matcher == config::MatcherType::kLearned && !odometry.putative_filter) {
    Result<vision::CorrespondenceFilter> filter = vision::CorrespondenceFilter::load_default();
    if (!filter) return Error("vision.matcher learned: " + filter.error().message, "vision.matcher");
    odometry.putative_filter = std::make_shared<const vision::CorrespondenceFilter>(std::move(filter).value());
  }
  return ok_status();
}

}  // namespace

Result<std::unique_ptr<CameraOdometry>> CameraOdometry::create(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                               const vision::VisualOdometryConfig& odometry_config) {
  std::vector<const calib::SensorCalibration*> cameras;
  for (const config::SensorConfig& sensor : config.sensors) {
    if (sensor.modality != config::SensorModality::kCamera) continue;
    const calib::SensorCalibration* entry = calibration.find(sensor.name);
    if (entry != nullptr && entry->camera && cameras.size() < 2) cameras.push_back(entry);
  }
  if (cameras.empty()) return std::unique_ptr<CameraOdometry>();
  const calib::SensorCalibration& left = *cameras[0];
  const msgs::CameraIntrinsics& intrinsics = left.camera->intrinsics;
  if (intrinsics.width == 0 || intrinsics.height == 0) {
    return Error(fmt::format("camera {}: the calibration's intrinsics need the image width and height for visual odometry", left.sensor));
  }
  const cv::Size size(static_cast<int>(intrinsics.width), static_cast<int>(intrinsics.height));
  const bool stereo_pair = cameras.size() == 2 && cameras[1]->camera->intrinsics.width == intrinsics.width &&
                           cameras[1]->camera->intrinsics.height == intrinsics.height;
  if (config.frontend.type == config::FrontendType::kMsckf) return create_visual_inertial(config, calibration, cameras, stereo_pair, size);
  // A monocular camera beside an IMU needs the visual-inertial frontend for its scale: the
  // loosely coupled filters cannot use its poses, so its images are not processed at all.
  const bool has_imu = std::any_of(config.sensors.begin(), config.sensors.end(),
                                   [](const config::SensorConfig& sensor) { return sensor.modality == config::SensorModality::kImu; });
  if (has_imu && !stereo_pair) {
    logger()->warn("camera '{}' is not used by frontend.type {} beside an IMU (a single camera's scale needs the visual-inertial "
                   "frontend, frontend.type: msckf); its images are counted as not_fused",
                   left.sensor, config::to_string(config.frontend.type));
    return std::unique_ptr<CameraOdometry>();
  }
  vision::VisualOdometryConfig configured = odometry_config;
  HANZO_RETURN_IF_ERROR(apply_vision_config(config, left.sensor, stereo_pair ? cameras[1]->sensor : "", configured));
  std::unique_ptr<vision::VisualOdometry> odometry;
  std::string right_sensor;
  Duration right_offset;
  if (stereo_pair) {
    const calib::SensorCalibration& right = *cameras[1];
    HANZO_ASSIGN_OR_RETURN(odometry, with_context(vision::VisualOdometry::create_stereo(left.camera->pinhole_camera(), right.camera->pinhole_camera(),
                                                                                         left.T_body_sensor().inverse() * right.T_body_sensor(), size,
                                                                                         configured),
                                                  fmt::format("cameras {} and {}", left.sensor, right.sensor)));
    right_sensor = right.sensor;
    right_offset = right.time_offset;
  } else {
    HANZO_ASSIGN_OR_RETURN(odometry, with_context(vision::VisualOdometry::create(left.camera->pinhole_camera(), size, configured),
                                                  fmt::format("camera {}", left.sensor)));
  }
  logger()->info("session: {} visual odometry on {}{} ({} features{})", right_sensor.empty() ? "monocular" : "stereo", left.sensor,
                 right_sensor.empty() ? "" : " + " + right_sensor, configured.extractor->name(),
                 configured.putative_filter ? ", learned correspondence filter" : "");
  return std::unique_ptr<CameraOdometry>(
      new CameraOdometry(std::move(odometry), left.sensor, std::move(right_sensor), left.camera->pinhole_camera(), left.T_body_sensor(),
                                                            left.time_offset, right_offset));
}

Result<std::unique_ptr<CameraOdometry>> CameraOdometry::create_visual_inertial(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                                               const std::vector<const calib::SensorCalibration*>& cameras,
                                                                               bool stereo_pair, cv::Size size) {
  const auto imu = std::find_if(config.sensors.begin(), config.sensors.end(),
                                [](const config::SensorConfig& sensor) { return sensor.modality == config::SensorModality::kImu; });
  if (imu == config.sensors.end()) return Error("frontend.type msckf: visual-inertial odometry needs an IMU sensor", "frontend.type");
  SE3 T_body_imu;
  Duration imu_offset;
  if (const calib::SensorCalibration* entry = calibration.find(imu->name)) {
    T_body_imu = entry->T_body_sensor();
    imu_offset = entry->time_offset;
  }
  std::vector<MsckfCameraSetup> setups;
  for (size_t i = 0; i < (stereo_pair ? 2u : 1u); ++i) setups.push_back({cameras[i]->camera->pinhole_camera(), cameras[i]->T_body_sensor()});
  const config::CovarianceConfig& covariance = config.frontend.covariance;
  const estimate::ImuNoise noise{covariance.process_noise_accel, covariance.process_noise_gyro, covariance.accel_bias_random_walk,
                                 covariance.gyro_bias_random_walk, 1.0 / imu->rate_hz};
  // Learned features detect the tracker's new features; the classical detector is Shi-Tomasi's.
  vision::FeatureTrackerConfig tracker;
  std::pair<config::FeatureSelection, std::string> features;
  HANZO_ASSIGN_OR_RETURN(features, configured_features(config, cameras[0]->sensor, stereo_pair ? cameras[1]->sensor : ""));
  if (features.first.learned()) {
    HANZO_ASSIGN_OR_RETURN(tracker.detector, make_feature_extractor(features.first, kTrackerCandidates * tracker.max_features, features.second));
  }
  if (config.vision.place_recognition == config::PlaceRecognitionType::kLearned) {
    logger()->warn("vision.place_recognition learned: the visual-inertial odometry's loop detector ranks places by bags of ORB words");
  }
  if (config.vision.matcher == config::MatcherType::kLearned) {
    logger()->warn("vision.matcher learned: the visual-inertial odometry follows features by optical flow (no descriptor matches to "
                   "filter); its tracks are checked by RANSAC");
  }
  std::unique_ptr<MsckfOdometry> inertial;
  HANZO_ASSIGN_OR_RETURN(inertial, with_context(MsckfOdometry::create(setups, size, T_body_imu, noise, tracker), fmt::format("camera {}", cameras[0]->sensor)));
  const calib::SensorCalibration& left = *cameras[0];
  logger()->info("session: {} visual-inertial odometry (MSCKF) on {}{} and {}", stereo_pair ? "stereo" : "monocular", left.sensor,
                 stereo_pair ? " + " + cameras[1]->sensor : "", imu->name);
  auto odometry = std::unique_ptr<CameraOdometry>(new CameraOdometry(nullptr, left.sensor, stereo_pair ? cameras[1]->sensor : "", left.camera->pinhole_camera(), left.T_body_sensor(),
                                                                     left.time_offset, stereo_pair ? cameras[1]->time_offset : Duration()));
  odometry->inertial_ = std::move(inertial);
  std::vector<VisualInertialFactors::Camera> factor_cameras;
  for (const MsckfCameraSetup& setup : setups) factor_cameras.push_back({setup.T_body_camera, setup.camera.fx});
  const ImuChainNoise chain = imu_chain_noise(config, *imu);
  odometry->keyframe_factors_ = std::make_unique<VisualInertialFactors>(std::move(factor_cameras), chain.preintegration, chain.accel_bias_random_walk,
                                                                        chain.gyro_bias_random_walk);
  odometry->T_body_imu_ = T_body_imu;
  odometry->imu_sensor_ = imu->name;
  odometry->imu_offset_ = imu_offset;
  odometry->body_imu_.emplace(T_body_imu, imu_offset);
  odometry->inertial_summary_.scale_free = false;
  odometry->inertial_summary_.features = tracker.detector ? tracker.detector->name() : "shi-tomasi";
  return odometry;
}

void CameraOdometry::add_imu(const msgs::ImuMessage& imu) {
  if (!inertial_ || !imu.angular_velocity.allFinite() || !imu.linear_acceleration.allFinite()) return;
  inertial_->add_imu({imu.timestamp + imu_offset_, imu.angular_velocity, imu.linear_acceleration});
  if (const std::optional<estimate::ImuSample> sample = body_imu_->convert(imu)) keyframe_factors_->add_imu(*sample);
}

std::optional<graph::ImuBias> CameraOdometry::imu_bias_body() const {
  if (!inertial_) return std::nullopt;
  const auto bias = inertial_->imu_bias();
  if (!bias) return std::nullopt;
  graph::ImuBias body;
  body.accelerometer = T_body_imu_.rotation() * bias->first;
  body.gyroscope = T_body_imu_.rotation() * bias->second;
  return body;
}

vision::VisualOdometrySummary CameraOdometry::summary() const {
  if (!inertial_) return odometry_->summary();
  vision::VisualOdometrySummary summary = inertial_summary_;
  summary.standstill_frames = inertial_->zero_velocity_frames();
  return summary;
}

CameraOdometry::CameraOdometry(std::unique_ptr<vision::VisualOdometry> odometry, std::string left_sensor, std::string right_sensor,
                               const PinholeCamera& left_camera, const SE3& T_body_left, Duration left_offset, Duration right_offset)
    : odometry_(std::move(odometry)),
      left_sensor_(std::move(left_sensor)),
      right_sensor_(std::move(right_sensor)),
      left_camera_(left_camera),
      T_body_left_(T_body_left),
      left_offset_(left_offset),
      right_offset_(right_offset) {}

Result<std::optional<CameraOdometry::Tracked>> CameraOdometry::add(std::string_view sensor, const msgs::ImageMessage& image) {
  cv::Mat grey;
  HANZO_ASSIGN_OR_RETURN(grey, vision::grey_image(image));
  if (sensor == left_sensor_) {
    const Timestamp time = image.timestamp + left_offset_;
    if (!stereo()) return track(time, grey, cv::Mat());
    // A left image still waiting lost its right one: tracked alone is not possible for a
    // stereo odometry, so it is dropped.
    if (waiting_left_) logger()->debug("session: left image at {:.3f} s had no right image", waiting_left_->first.seconds());
    waiting_left_.emplace(time, std::move(grey));
    return std::optional<Tracked>();
  }
  const Timestamp time = image.timestamp + right_offset_;
  if (!waiting_left_ || std::abs((waiting_left_->first - time).seconds()) > 1e-3) {
    logger()->debug("session: right image at {:.3f} s has no left image of its time: dropped", time.seconds());
    return std::optional<Tracked>();
  }
  const auto [left_time, left] = std::move(*waiting_left_);
  waiting_left_.reset();
  return track(left_time, left, grey);
}

Result<std::optional<CameraOdometry::Tracked>> CameraOdometry::track(Timestamp time, const cv::Mat& left, const cv::Mat& right) {
  vision::ImageQuality quality;
  HANZO_ASSIGN_OR_RETURN(quality, image_quality_.assess(left));
  switch (quality.condition) {
    case vision::ImageCondition::kGood: break;
    case vision::ImageCondition::kDark: ++image_conditions_.dark; break;
    case vision::ImageCondition::kGlare: ++image_conditions_.glare; break;
    case vision::ImageCondition::kMotionBlur: ++image_conditions_.motion_blur; break;
  }
  if (inertial_) {
    MsckfOdometry::Frame frame;
    HANZO_ASSIGN_OR_RETURN(frame, inertial_->track(time, left, right));
    Tracked tracked;
    tracked.time = time;
    tracked.T_world_body = frame.T_world_body;
    tracked.image_quality = quality;
    tracked.left_image = left;
    tracked.frame.time = time.seconds();
    tracked.frame.state = frame.tracking ? vision::TrackingState::kTracking : vision::TrackingState::kInitializing;
    tracked.frame.standing_still = frame.update.zero_velocity;
    tracked.frame.reason = frame.reason;
    if (frame.tracking && (quality.condition == vision::ImageCondition::kDark || frame.tracked_features < kMinTrackedFeatures)) {
      tracked.frame.state = vision::TrackingState::kLost;
      tracked.frame.reason = quality.condition == vision::ImageCondition::kDark
                                 ? fmt::format("dark image (mean grey level {:.0f})", quality.mean_intensity)
                                 : fmt::format("{} features continued from the previous image ({} image)", frame.tracked_features,
                                               vision::to_string(quality.condition));
    }
    if (frame.tracking) {
      keyframe_factors_->add_frame(time, frame.T_world_body, std::move(frame.observations));
    } else {
      keyframe_factors_->odometry_restarted();  // (re)initializing: a new odometry world follows
    }
    ++inertial_summary_.frames;
    ++inertial_summary_.feature_frames;
    inertial_summary_.feature_seconds += frame.feature_seconds;
    inertial_summary_.tracked_frames += tracked.frame.state == vision::TrackingState::kTracking;
    inertial_summary_.lost_frames += tracked.frame.state == vision::TrackingState::kLost;
    return std::optional<Tracked>(std::move(tracked));
  }
  Result<vision::VisualOdometryFrame> frame = right.empty() ? odometry_->track(time.seconds(), left) : odometry_->track(time.seconds(), left, right);
  if (!frame) return frame.error();
  Tracked tracked{time, std::move(frame).value(), SE3(), quality, left};
  tracked.T_world_body = T_body_left_ * tracked.frame.T_world_camera * T_body_left_.inverse();
  return std::optional<Tracked>(std::move(tracked));
}

}  // namespace hanzo::fusion::pipeline
