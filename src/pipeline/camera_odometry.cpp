#include "camera_odometry.hpp"

#include <algorithm>
#include <set>

#include <fmt/format.h>
#include <fmt/ranges.h>
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
  odometry.local_mapping_thread = config.vision.local_mapping_thread;
  if (config.vision.matcher == config::MatcherType::kLearned && !odometry.putative_filter) {
    Result<vision::CorrespondenceFilter> filter = vision::CorrespondenceFilter::load_default();
    if (!filter) return Error("vision.matcher learned: " + filter.error().message, "vision.matcher");
    odometry.putative_filter = std::make_shared<const vision::CorrespondenceFilter>(std::move(filter).value());
  }
  return ok_status();
}

// A depth image's pixels (copied: the frame may wait for its colour image after the message is
// gone): depth16 millimetres as CV_16UC1, depth32f metres as CV_32FC1.
Result<cv::Mat> depth_image(const msgs::ImageMessage& image) {
  const bool millimetres = image.encoding == msgs::ImageEncoding::kDepth16;
  if (!millimetres && image.encoding != msgs::ImageEncoding::kDepth32f) {
    return Error(fmt::format("depth camera {}: encoding {} is not a depth image (depth16, depth32f)", image.frame_id, msgs::to_string(image.encoding)));
  }
  const std::size_t needed = std::size_t{image.width} * image.height * (millimetres ? 2U : 4U);
  if (image.data.size() != needed) {
    return Error(fmt::format("depth camera {}: {} bytes, {} x {} {} takes {}", image.frame_id, image.data.size(), image.width, image.height,
                             msgs::to_string(image.encoding), needed));
  }
  return cv::Mat(static_cast<int>(image.height), static_cast<int>(image.width), millimetres ? CV_16UC1 : CV_32FC1,
                 const_cast<uint8_t*>(image.data.data()))
      .clone();
}

}  // namespace

Result<std::unique_ptr<CameraOdometry>> CameraOdometry::create(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                               const vision::VisualOdometryConfig& odometry_config) {
  // The cameras with intrinsics in the configuration's order, grouped into rigs (header comment).
  std::vector<std::vector<const calib::SensorCalibration*>> rigs;
  std::set<std::size_t> depth_rigs;  // rigs whose second camera is the first's depth images
  const auto size_of = [](const calib::SensorCalibration& camera) {
    return cv::Size(static_cast<int>(camera.camera->intrinsics.width), static_cast<int>(camera.camera->intrinsics.height));
  };
  for (const config::SensorConfig& sensor : config.sensors) {
    if (sensor.modality != config::SensorModality::kCamera) continue;
    const calib::SensorCalibration* entry = calibration.find(sensor.name);
    if (entry == nullptr || !entry->camera) continue;
    if (size_of(*entry).area() == 0) {
      if (rigs.empty()) {
        return Error(fmt::format("camera {}: the calibration's intrinsics need the image width and height for visual odometry", entry->sensor));
      }
      logger()->warn("camera {}: not used by the visual odometry (the calibration's intrinsics have no image size)", entry->sensor);
      continue;
    }
    const bool depth = sensor.type == config::kDepthCameraType;
    if (!rigs.empty() && rigs.back().size() == 1 && size_of(*rigs.back()[0]) == size_of(*entry)) {
      rigs.back().push_back(entry);
      if (depth) depth_rigs.insert(rigs.size() - 1);
    } else if (depth) {
      logger()->warn("camera {}: depth images without a colour camera of their size configured just before them: not used", entry->sensor);
    } else {
      rigs.push_back({entry});
    }
  }
  if (rigs.empty()) return std::unique_ptr<CameraOdometry>();
  if (config.frontend.type == config::FrontendType::kMsckf) {
    for (const std::size_t rig : depth_rigs) {
      logger()->warn("camera {}: the visual-inertial odometry does not use depth images (its camera {} is tracked alone)", rigs[rig][1]->sensor,
                     rigs[rig][0]->sensor);
      rigs[rig].pop_back();
    }
    return create_visual_inertial(config, calibration, rigs);
  }
  const calib::SensorCalibration& left = *rigs[0][0];
  const bool rgbd = depth_rigs.count(0) > 0;
  const bool stereo_pair = rigs[0].size() == 2 && !rgbd;
  const cv::Size size = size_of(left);
  for (size_t rig = 1; rig < rigs.size(); ++rig) {
    for (const calib::SensorCalibration* camera : rigs[rig]) {
      logger()->warn("camera '{}' is not used: frontend.type {}'s visual odometry takes one camera or stereo pair ({}; frontend.type msckf "
                     "takes several)", camera->sensor, config::to_string(config.frontend.type), left.sensor);
    }
  }
  // A monocular camera beside an IMU needs the visual-inertial frontend for its scale: the
  // loosely coupled filters cannot use its poses, so its images are not processed at all.
  const bool has_imu = std::any_of(config.sensors.begin(), config.sensors.end(),
                                   [](const config::SensorConfig& sensor) { return sensor.modality == config::SensorModality::kImu; });
  if (has_imu && !stereo_pair && !rgbd) {
    logger()->warn("camera '{}' is not used by frontend.type {} beside an IMU (a single camera's scale needs the visual-inertial "
                   "frontend, frontend.type: msckf); its images are counted as not_fused",
                   left.sensor, config::to_string(config.frontend.type));
    return std::unique_ptr<CameraOdometry>();
  }
  vision::VisualOdometryConfig configured = odometry_config;
  HANZO_RETURN_IF_ERROR(apply_vision_config(config, left.sensor, stereo_pair ? rigs[0][1]->sensor : "", configured));
  std::unique_ptr<vision::VisualOdometry> odometry;
  Rig rig{left.sensor, "", left.time_offset, Duration(), size, left.camera->pinhole_camera(), left.T_body_sensor()};
  if (rgbd) {
    const calib::SensorCalibration& depth = *rigs[0][1];
    HANZO_ASSIGN_OR_RETURN(odometry, with_context(vision::VisualOdometry::create_rgbd(left.camera->pinhole_camera(), size, configured),
                                                  fmt::format("cameras {} and {}", left.sensor, depth.sensor)));
    rig.right_sensor = depth.sensor;
    rig.right_offset = depth.time_offset;
    rig.depth = true;
  } else if (stereo_pair) {
    const calib::SensorCalibration& right = *rigs[0][1];
    HANZO_ASSIGN_OR_RETURN(odometry, with_context(vision::VisualOdometry::create_stereo(left.camera->pinhole_camera(), right.camera->pinhole_camera(),
                                                                                         left.T_body_sensor().inverse() * right.T_body_sensor(), size,
                                                                                         configured),
                                                  fmt::format("cameras {} and {}", left.sensor, right.sensor)));
    rig.right_sensor = right.sensor;
    rig.right_offset = right.time_offset;
  } else {
    HANZO_ASSIGN_OR_RETURN(odometry, with_context(vision::VisualOdometry::create(left.camera->pinhole_camera(), size, configured),
                                                  fmt::format("camera {}", left.sensor)));
  }
  logger()->info("session: {} visual odometry on {}{} ({} features{})", rgbd ? "RGB-D" : stereo_pair ? "stereo" : "monocular", left.sensor,
                 rig.right_sensor.empty() ? "" : " + " + rig.right_sensor, configured.extractor->name(),
                 configured.putative_filter ? ", learned correspondence filter" : "");
  auto created = std::unique_ptr<CameraOdometry>(new CameraOdometry(std::move(odometry), {rig}));
  created->extractor_ = configured.extractor;
  return created;
}

Result<std::unique_ptr<CameraOdometry>> CameraOdometry::create_visual_inertial(const config::FusionConfig& config, const calib::Calibration& calibration,
                                                                               const std::vector<std::vector<const calib::SensorCalibration*>>& camera_rigs) {
  const auto imu = std::find_if(config.sensors.begin(), config.sensors.end(),
                                [](const config::SensorConfig& sensor) { return sensor.modality == config::SensorModality::kImu; });
  if (imu == config.sensors.end()) return Error("frontend.type msckf: visual-inertial odometry needs an IMU sensor", "frontend.type");
  SE3 T_body_imu;
  Duration imu_offset;
  if (const calib::SensorCalibration* entry = calibration.find(imu->name)) {
    T_body_imu = entry->T_body_sensor();
    imu_offset = entry->time_offset;
  }
  const config::CovarianceConfig& covariance = config.frontend.covariance;
  const estimate::ImuNoise noise{covariance.process_noise_accel, covariance.process_noise_gyro, covariance.accel_bias_random_walk,
                                 covariance.gyro_bias_random_walk, 1.0 / imu->rate_hz};
  // Learned features detect the tracker's new features; the classical detector is Shi-Tomasi's.
  // Every rig tracks the same kind.
  std::vector<MsckfRigSetup> setups;
  std::vector<Rig> rigs;
  std::vector<std::string> rig_names;
  std::optional<config::FeatureSelection> rig0_features;
  vision::FeatureTrackerConfig tracker;
  for (const std::vector<const calib::SensorCalibration*>& cameras : camera_rigs) {
    const calib::SensorCalibration& left = *cameras[0];
    const bool stereo = cameras.size() == 2;
    std::pair<config::FeatureSelection, std::string> features;
    HANZO_ASSIGN_OR_RETURN(features, configured_features(config, left.sensor, stereo ? cameras[1]->sensor : ""));
    if (!rig0_features) {
      rig0_features = features.first;
      if (features.first.learned()) {
        HANZO_ASSIGN_OR_RETURN(tracker.detector, make_feature_extractor(features.first, kTrackerCandidates * tracker.max_features, features.second));
      }
    } else if (!(features.first == *rig0_features)) {
      return Error(fmt::format("{}: {} differs from {}'s {} (the visual-inertial odometry tracks one kind of feature)", features.second,
                               features.first.type, rigs[0].left_sensor, rig0_features->type),
                   features.second);
    }
    MsckfRigSetup setup;
    setup.image_size = cv::Size(static_cast<int>(left.camera->intrinsics.width), static_cast<int>(left.camera->intrinsics.height));
    for (const calib::SensorCalibration* camera : cameras) setup.cameras.push_back({camera->camera->pinhole_camera(), camera->T_body_sensor()});
    rigs.push_back({left.sensor, stereo ? cameras[1]->sensor : "", left.time_offset, stereo ? cameras[1]->time_offset : Duration(), setup.image_size,
                    left.camera->pinhole_camera(), left.T_body_sensor()});
    rig_names.push_back(stereo ? fmt::format("stereo {} + {}", left.sensor, cameras[1]->sensor) : fmt::format("monocular {}", left.sensor));
    setups.push_back(std::move(setup));
  }
  if (config.vision.place_recognition == config::PlaceRecognitionType::kLearned) {
    logger()->warn("vision.place_recognition learned: the visual-inertial odometry's loop detector ranks places by bags of ORB words");
  }
  if (config.vision.matcher == config::MatcherType::kLearned) {
    logger()->warn("vision.matcher learned: the visual-inertial odometry follows features by optical flow (no descriptor matches to "
                   "filter); its tracks are checked by RANSAC");
  }
  std::unique_ptr<MsckfOdometry> inertial;
  HANZO_ASSIGN_OR_RETURN(inertial, with_context(MsckfOdometry::create(setups, T_body_imu, noise, tracker), fmt::format("camera {}", rigs[0].left_sensor)));
  logger()->info("session: visual-inertial odometry (MSCKF) on {} and {}", fmt::join(rig_names, ", "), imu->name);
  auto odometry = std::unique_ptr<CameraOdometry>(new CameraOdometry(nullptr, std::move(rigs)));
  odometry->inertial_ = std::move(inertial);
  std::vector<VisualInertialFactors::Camera> factor_cameras;
  for (size_t rig = 0; rig < setups.size(); ++rig) {
    for (const MsckfCameraSetup& camera : setups[rig].cameras) factor_cameras.push_back({camera.T_body_camera, camera.camera.fx, static_cast<int>(rig)});
  }
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

CameraOdometry::CameraOdometry(std::unique_ptr<vision::VisualOdometry> odometry, std::vector<Rig> rigs)
    : odometry_(std::move(odometry)), rigs_(std::move(rigs)) {}

const CameraOdometry::Rig* CameraOdometry::rig_of(std::string_view sensor) const {
  for (const Rig& rig : rigs_) {
    if (sensor == rig.left_sensor || (!rig.right_sensor.empty() && sensor == rig.right_sensor)) return &rig;
  }
  return nullptr;
}

Result<std::optional<CameraOdometry::Tracked>> CameraOdometry::add(std::string_view sensor, const msgs::ImageMessage& image, const vision::StaticMask& static_mask) {
  // Images of one frame are at most this far apart (seconds, body clock).
  constexpr double kFrameTolerance = 1e-3;
  const Rig* rig = rig_of(sensor);
  if (rig == nullptr) return Error(fmt::format("camera {}: not a camera of the visual odometry", sensor));
  const bool left = sensor == rig->left_sensor;
  cv::Mat grey;
  if (!left && rig->depth) {
    HANZO_ASSIGN_OR_RETURN(grey, depth_image(image));
  } else {
    HANZO_ASSIGN_OR_RETURN(grey, vision::grey_image(image));
  }
  const Timestamp time = image.timestamp + (left ? rig->left_offset : rig->right_offset);
  std::optional<Tracked> tracked;
  if (pending_ && std::abs((time - pending_->time).seconds()) > kFrameTolerance) {
    if (time < pending_->time) {
      logger()->debug("session: camera {}: image at {:.3f} s is older than the frame waiting ({:.3f} s): dropped", sensor, time.seconds(),
                      pending_->time.seconds());
      return std::optional<Tracked>();
    }
    HANZO_ASSIGN_OR_RETURN(tracked, track_pending());
  }
  if (!pending_) pending_ = PendingFrame{time, std::nullopt, std::vector<std::pair<cv::Mat, cv::Mat>>(rigs_.size()), std::vector<vision::StaticMask>(rigs_.size())};
  const size_t index = static_cast<size_t>(rig - rigs_.data());
  std::pair<cv::Mat, cv::Mat>& images = pending_->images[index];
  (left ? images.first : images.second) = std::move(grey);
  if (left) pending_->static_masks[index] = static_mask;
  if (left && (!pending_->left_time || index == 0)) pending_->left_time = time;
  const bool complete = std::all_of(rigs_.begin(), rigs_.end(), [this](const Rig& each) {
    const std::pair<cv::Mat, cv::Mat>& frame = pending_->images[static_cast<size_t>(&each - rigs_.data())];
    return !frame.first.empty() && (each.right_sensor.empty() || !frame.second.empty());
  });
  // (A frame that completes with this image was just started only for a single camera, which
  // never leaves one waiting: at most one frame is tracked per image.)
  if (complete) HANZO_ASSIGN_OR_RETURN(tracked, track_pending());
  return tracked;
}

Result<std::optional<CameraOdometry::Tracked>> CameraOdometry::track_pending() {
  PendingFrame frame = std::move(*pending_);
  pending_.reset();
  std::vector<MsckfOdometry::RigImages> images;
  std::vector<std::string> sensors;
  for (size_t index = 0; index < rigs_.size(); ++index) {
    const Rig& rig = rigs_[index];
    auto& [left, right] = frame.images[index];
    if (left.empty() || (!rig.right_sensor.empty() && right.empty())) {
      if (!left.empty() || !right.empty()) {
        logger()->debug("session: camera {}: image at {:.3f} s has no {} image of its time: dropped", left.empty() ? rig.right_sensor : rig.left_sensor,
                        frame.time.seconds(), left.empty() ? "left" : "right");
      }
      continue;
    }
    images.push_back({static_cast<int>(index), std::move(left), std::move(right), frame.static_masks[index]});
    sensors.push_back(rig.left_sensor);
    if (!rig.right_sensor.empty()) sensors.push_back(rig.right_sensor);
  }
  if (images.empty()) return std::optional<Tracked>();
  const Timestamp time = *frame.left_time;
  Tracked tracked;
  if (inertial_) {
    HANZO_ASSIGN_OR_RETURN(tracked, track_inertial(time, images));
  } else {
    // The visual odometry's single rig.
    const cv::Mat& left = images[0].left;
    vision::ImageQuality quality;
    HANZO_ASSIGN_OR_RETURN(quality, assess(left));
    const vision::StaticMask& mask = images[0].static_mask;
    Result<vision::VisualOdometryFrame> odometry_frame = images[0].right.empty() ? odometry_->track(time.seconds(), left, mask)
                                                         : rigs_[0].depth        ? odometry_->track_rgbd(time.seconds(), left, images[0].right, mask)
                                                                                 : odometry_->track(time.seconds(), left, images[0].right, mask);
    if (!odometry_frame) return odometry_frame.error();
    tracked = Tracked{time, std::move(odometry_frame).value(), SE3(), quality, {{0, left}}, {mask}, {}};
    tracked.T_world_body = T_body_left() * tracked.frame.T_world_camera * T_body_left().inverse();
  }
  tracked.sensors = std::move(sensors);
  return std::optional<Tracked>(std::move(tracked));
}

Result<vision::ImageQuality> CameraOdometry::assess(const cv::Mat& left) {
  vision::ImageQuality quality;
  HANZO_ASSIGN_OR_RETURN(quality, image_quality_.assess(left));
  switch (quality.condition) {
    case vision::ImageCondition::kGood: break;
    case vision::ImageCondition::kDark: ++image_conditions_.dark; break;
    case vision::ImageCondition::kGlare: ++image_conditions_.glare; break;
    case vision::ImageCondition::kMotionBlur: ++image_conditions_.motion_blur; break;
  }
  return quality;
}

Result<CameraOdometry::Tracked> CameraOdometry::track_inertial(Timestamp time, const std::vector<MsckfOdometry::RigImages>& images) {
  // The frame's image quality: the first good left image's, else rig order's first.
  std::optional<vision::ImageQuality> quality;
  for (const MsckfOdometry::RigImages& rig : images) {
    vision::ImageQuality assessed;
    HANZO_ASSIGN_OR_RETURN(assessed, assess(rig.left));
    if (!quality || (quality->condition != vision::ImageCondition::kGood && assessed.condition == vision::ImageCondition::kGood)) quality = assessed;
  }
  MsckfOdometry::Frame frame;
  HANZO_ASSIGN_OR_RETURN(frame, inertial_->track(time, images));
  Tracked tracked;
  tracked.time = time;
  tracked.T_world_body = frame.T_world_body;
  tracked.image_quality = *quality;
  for (const MsckfOdometry::RigImages& rig : images) {
    tracked.left_images.emplace_back(rig.rig, rig.left);
    tracked.left_masks.push_back(rig.static_mask);
  }
  tracked.frame.time = time.seconds();
  tracked.frame.state = frame.tracking ? vision::TrackingState::kTracking : vision::TrackingState::kInitializing;
  tracked.frame.standing_still = frame.update.zero_velocity;
  tracked.frame.reason = frame.reason;
  if (frame.tracking && (quality->condition == vision::ImageCondition::kDark || frame.tracked_features < kMinTrackedFeatures)) {
    tracked.frame.state = vision::TrackingState::kLost;
    tracked.frame.reason = quality->condition == vision::ImageCondition::kDark
                               ? fmt::format("dark image (mean grey level {:.0f})", quality->mean_intensity)
                               : fmt::format("{} features continued from the previous image ({} image)", frame.tracked_features,
                                             vision::to_string(quality->condition));
  }
  if (frame.tracking) {
    std::vector<int> rigs;
    for (const MsckfOdometry::RigImages& rig : images) rigs.push_back(rig.rig);
    keyframe_factors_->add_frame(time, frame.T_world_body, std::move(frame.observations), std::move(rigs));
  } else {
    keyframe_factors_->odometry_restarted();  // (re)initializing: a new odometry world follows
  }
  ++inertial_summary_.frames;
  ++inertial_summary_.feature_frames;
  inertial_summary_.feature_seconds += frame.feature_seconds;
  inertial_summary_.tracked_frames += tracked.frame.state == vision::TrackingState::kTracking;
  inertial_summary_.lost_frames += tracked.frame.state == vision::TrackingState::kLost;
  return tracked;
}

}  // namespace hanzo::fusion::pipeline
