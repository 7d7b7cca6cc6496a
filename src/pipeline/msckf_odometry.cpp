#include "msckf_odometry.hpp"

#include <algorithm>
#include <chrono>

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/estimate/attitude_models.hpp"
#include "hanzo/fusion/estimate/static_alignment.hpp"
#include "moving_start.hpp"

namespace hanzo::fusion::pipeline {
namespace {

constexpr double kAlignmentSeconds = 1.0;  // still IMU used to start the filter
constexpr size_t kMaxBufferedSamples = 20000;
// Initial velocity standard deviations of a start in motion without the visual-inertial
// alignment (m/s): unknown, or measured from two stereo frames.
constexpr double kMovingStartVelocitySigma = 1.0;
constexpr double kStereoVelocitySigma = 0.2;
// In motion (one camera or two): the window of camera 0's frames aligned with the IMU, how long
// alignment may keep failing before the start without it, and the start's standard deviations
// after alignment (velocity, roll/pitch, gyro bias). Window and sigmas chosen over seven
// simulated starts in motion (bench/RESULTS.md, 2026-11-29): a 1 s or 2 s window, or 0.3 m/s,
// diverged on one.
constexpr double kVisualInertialWindowSeconds = 1.5;
constexpr double kMaxAligningSeconds = 2.0;
constexpr double kAlignedVelocitySigma = 0.5;
constexpr double kAlignedTiltSigma = 0.01;
constexpr double kAlignedGyroBiasSigma = 0.01;
// IMU kept before the start: the alignment window and a margin.
constexpr double kPreStartImuSeconds = kVisualInertialWindowSeconds + 1.0;
constexpr size_t kMaxRigs = 4;
// Feature ids of rig r carry r above bit 48: unique across the rigs' trackers, and within the
// 56-bit index of a graph key (graph/keys.hpp: landmarks are keyed by feature id).
constexpr int kRigIdShift = 48;

}  // namespace

Result<std::unique_ptr<MsckfOdometry>> MsckfOdometry::create(const std::vector<MsckfRigSetup>& rigs, const SE3& T_body_imu,
                                                             const estimate::ImuNoise& imu_noise, const vision::FeatureTrackerConfig& tracker_config) {
  if (rigs.empty() || rigs.size() > kMaxRigs) return Error(fmt::format("MsckfOdometry: {} camera rigs; 1 to {} are supported", rigs.size(), kMaxRigs));
  std::vector<Rig> trackers;
  std::vector<vision::MsckfCamera> msckf_cameras;
  for (size_t index = 0; index < rigs.size(); ++index) {
    const std::vector<MsckfCameraSetup>& cameras = rigs[index].cameras;
    if (cameras.empty() || cameras.size() > 2) return Error(fmt::format("MsckfOdometry: rig {} has {} cameras; one or two", index, cameras.size()));
    Rig rig;
    rig.first_camera = static_cast<int>(msckf_cameras.size());
    rig.stereo = cameras.size() == 2;
    if (rig.stereo) {
      HANZO_ASSIGN_OR_RETURN(rig.tracker, vision::FeatureTracker::create_stereo(cameras[0].camera, cameras[1].camera,
                                                                                cameras[0].T_body_camera.inverse() * cameras[1].T_body_camera,
                                                                                rigs[index].image_size, tracker_config));
    } else {
      HANZO_ASSIGN_OR_RETURN(rig.tracker, vision::FeatureTracker::create(cameras[0].camera, rigs[index].image_size, tracker_config));
    }
    for (const MsckfCameraSetup& setup : cameras) {
      msckf_cameras.push_back({T_body_imu.inverse() * setup.T_body_camera, setup.camera.fx, static_cast<int>(index)});
    }
    trackers.push_back(std::move(rig));
  }
  return std::unique_ptr<MsckfOdometry>(new MsckfOdometry(std::move(trackers), std::move(msckf_cameras), T_body_imu, imu_noise));
}

MsckfOdometry::MsckfOdometry(std::vector<Rig> rigs, std::vector<vision::MsckfCamera> cameras, const SE3& T_body_imu,
                             const estimate::ImuNoise& imu_noise)
    : rigs_(std::move(rigs)), cameras_(std::move(cameras)), T_body_imu_(T_body_imu), imu_noise_(imu_noise) {}

void MsckfOdometry::add_imu(const estimate::ImuSample& sample) {
  if (!imu_.empty() && sample.timestamp <= imu_.back().timestamp) return;
  if (filter_ && sample.timestamp <= filter_->state().timestamp) return;
  imu_.push_back(sample);
  if (!filter_) {
    while (!imu_.empty() && (sample.timestamp - imu_.front().timestamp).seconds() > kPreStartImuSeconds) imu_.pop_front();
  } else {
    // No frames for a long time: propagate the oldest samples rather than keep them all.
    while (imu_.size() > kMaxBufferedSamples) {
      (void)filter_->propagate(imu_.front());
      imu_.pop_front();
    }
  }
}

std::optional<std::string> MsckfOdometry::start_filter(Timestamp time) {
  std::vector<estimate::ImuSample> still;
  for (const estimate::ImuSample& sample : imu_) {
    if (sample.timestamp <= time && (time - sample.timestamp).seconds() <= kAlignmentSeconds) still.push_back(sample);
  }
  if (still.size() < 2 || (still.back().timestamp - still.front().timestamp).seconds() < 0.8 * kAlignmentSeconds) {
    return std::string("initializing: waiting for a second of IMU data");
  }
  const Result<estimate::StaticAlignment> aligned = estimate::align_static(still, estimate::ImuMounting{}, 0.0);
  estimate::NavigationState state;
  state.timestamp = still.back().timestamp;
  state.gravity = Eigen::Vector3d(0.0, 0.0, -(aligned ? aligned->gravity_magnitude : estimate::kStandardGravity));
  Eigen::Matrix<double, 15, 1> sigma;
  if (aligned) {
    state.R_world_body = aligned->R_world_body;
    state.gyro_bias = aligned->gyro_bias;
    sigma << Eigen::Vector3d::Constant(1e-3), Eigen::Vector3d(0.02, 0.02, 1e-3), Eigen::Vector3d::Constant(0.02),
        Eigen::Vector3d::Constant(0.1), Eigen::Vector3d::Constant(0.005);
  } else {
    // In motion: the visual-inertial alignment of camera 0's first frames (tilt, velocity, gyro
    // bias); when it fails, the tilt from the IMU (moving_start.hpp) and the velocity from two
    // stereo frames, or, after 2 s of failures, unknown (zero, 1 m/s) for the images to find.
    std::string why;
    if (std::optional<vision::VisualInertialAlignment> aligned_in_motion = align_in_motion(time, why)) {
      state.R_world_body = aligned_in_motion->R_world_imu;
      state.velocity = aligned_in_motion->velocity_world;
      state.gyro_bias = aligned_in_motion->gyro_bias;
      sigma << Eigen::Vector3d::Constant(1e-3), Eigen::Vector3d(kAlignedTiltSigma, kAlignedTiltSigma, 1e-3), Eigen::Vector3d::Constant(kAlignedVelocitySigma),
          Eigen::Vector3d::Constant(0.1), Eigen::Vector3d::Constant(kAlignedGyroBiasSigma);
      logger()->info("msckf: starting in motion from the visual-inertial alignment of {} frames (velocity {:.2f} m/s, scale {:.3f}, gravity off by {:.1f} %)",
                     aligned_in_motion->frames, state.velocity.norm(), aligned_in_motion->scale, 100.0 * aligned_in_motion->gravity_error);
      return start_with(state, sigma, still.back());
    }
    // A stereo rig whose alignment failed starts from its two-frame velocity when it has one.
    const bool stereo_fallback = rigs_[0].stereo && stereo_velocity_ && aligning_since_;
    if (!stereo_fallback && (!aligning_since_ || (time - *aligning_since_).seconds() < kMaxAligningSeconds)) {
      return fmt::format("initializing: moving ({}); aligning the images with the IMU ({})", aligned.error().message, why);
    }
    logger()->info("msckf: the visual-inertial alignment failed ({}): starting from the IMU's tilt", why);
    state.R_world_body = tilt_from_moving_imu(still);
    double velocity_sigma = kMovingStartVelocitySigma;
    if (stereo_fallback) {
      state.velocity = state.R_world_body * *stereo_velocity_;
      velocity_sigma = kStereoVelocitySigma;
    }
    sigma << Eigen::Vector3d::Constant(1e-3), Eigen::Vector3d(0.05, 0.05, 1e-3), Eigen::Vector3d::Constant(velocity_sigma),
        Eigen::Vector3d::Constant(0.1), Eigen::Vector3d::Constant(0.01);
    logger()->info("msckf: starting in motion (roll {:.1f}, pitch {:.1f} degrees; velocity {:.2f} m/s{})",
                   estimate::roll_pitch_yaw(state.R_world_body.matrix()).x() * 180.0 / M_PI,
                   estimate::roll_pitch_yaw(state.R_world_body.matrix()).y() * 180.0 / M_PI, state.velocity.norm(),
                   velocity_sigma == kStereoVelocitySigma ? " from the stereo images" : ", unknown: the images will tell");
  }
  return start_with(state, sigma, still.back());
}

std::optional<std::string> MsckfOdometry::start_with(const estimate::NavigationState& state, const Eigen::Matrix<double, 15, 1>& sigma,
                                                     const estimate::ImuSample& last_sample) {
  vision::MsckfConfig config;
  config.imu_noise = imu_noise_;
  Result<vision::Msckf> filter = vision::Msckf::create(config, cameras_, state, sigma.array().square().matrix().asDiagonal().toDenseMatrix());
  if (!filter) return "initializing: " + filter.error().message;
  filter_.emplace(std::move(filter).value());
  previous_stereo_.reset();
  alignment_frames_.clear();
  aligning_since_.reset();
  (void)filter_->propagate(last_sample);
  while (!imu_.empty() && imu_.front().timestamp <= state.timestamp) imu_.pop_front();
  return std::nullopt;
}

std::optional<vision::VisualInertialAlignment> MsckfOdometry::align_in_motion(Timestamp time, std::string& why) {
  if (alignment_frames_.empty() || (time - alignment_frames_.front().time).seconds() < 0.95 * kVisualInertialWindowSeconds) {
    why = "collecting frames";
    return std::nullopt;
  }
  if (!aligning_since_) aligning_since_ = time;
  vision::VisualInertialAlignmentConfig config;
  config.focal_length_px = cameras_[0].focal_length_px;
  config.process_noise_accel = imu_noise_.process_noise_accel;
  config.process_noise_gyro = imu_noise_.process_noise_gyro;
  config.sample_interval = imu_noise_.sample_interval;
  const std::vector<vision::AlignmentFrame> frames(alignment_frames_.begin(), alignment_frames_.end());
  const std::vector<estimate::ImuSample> samples(imu_.begin(), imu_.end());
  Result<vision::VisualInertialAlignment> aligned = vision::align_visual_inertial(frames, samples, cameras_[0].T_body_camera, config);
  if (!aligned) {
    why = aligned.error().message;
    return std::nullopt;
  }
  return std::move(aligned).value();
}

std::optional<std::pair<Eigen::Vector3d, Eigen::Vector3d>> MsckfOdometry::imu_bias() const {
  if (!filter_) return std::nullopt;
  return std::make_pair(filter_->state().accel_bias, filter_->state().gyro_bias);
}

Result<MsckfOdometry::Frame> MsckfOdometry::track(Timestamp time, const std::vector<RigImages>& images) {
  Frame frame;
  std::vector<int> rigs_imaged;
  std::optional<std::vector<vision::FeatureObservation>> rig0_observations;
  const auto start = std::chrono::steady_clock::now();
  for (const RigImages& rig_images : images) {
    if (rig_images.rig < 0 || rig_images.rig >= static_cast<int>(rigs_.size()) ||
        std::find(rigs_imaged.begin(), rigs_imaged.end(), rig_images.rig) != rigs_imaged.end()) {
      return Error(fmt::format("MsckfOdometry: rig {} is not one of the {} rigs or comes twice in a frame", rig_images.rig, rigs_.size()));
    }
    const Rig& rig = rigs_[static_cast<size_t>(rig_images.rig)];
    vision::TrackedFrame tracked;
    HANZO_ASSIGN_OR_RETURN(tracked, rig.stereo ? rig.tracker->track(rig_images.left, rig_images.right, rig_images.static_mask)
                                                : rig.tracker->track(rig_images.left, rig_images.static_mask));
    rigs_imaged.push_back(rig_images.rig);
    frame.tracked_features += tracked.tracked;
    if (rig_images.rig == 0) rig0_observations = tracked.observations;
    for (vision::FeatureObservation& observation : tracked.observations) {
      observation.feature_id |= static_cast<uint64_t>(rig_images.rig) << kRigIdShift;
      observation.camera += rig.first_camera;
      frame.observations.push_back(observation);
    }
  }
  frame.feature_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  if (!filter_ && rig0_observations && rigs_[0].stereo) {
    // Before the start: the velocity from this and the previous stereo frame, in case it moves.
    std::map<uint64_t, Eigen::Vector3d> points = triangulate_stereo(*rig0_observations, cameras_);
    stereo_velocity_.reset();
    if (previous_stereo_) {
      const std::vector<estimate::ImuSample> samples(imu_.begin(), imu_.end());
      stereo_velocity_ = stereo_velocity(previous_stereo_->second, points, gyro_rotation(samples, previous_stereo_->first, time),
                                         (time - previous_stereo_->first).seconds());
    }
    previous_stereo_.emplace(time, std::move(points));
  }
  if (!filter_ && rig0_observations) {
    // Before the start: the window of rig 0's tracks for a start in motion.
    alignment_frames_.push_back({time, std::move(*rig0_observations)});
    while ((time - alignment_frames_.front().time).seconds() > kVisualInertialWindowSeconds) alignment_frames_.pop_front();
  }
  if (!filter_) {
    if (std::optional<std::string> waiting = start_filter(time)) {
      frame.reason = *waiting;
      return frame;
    }
  }
  const Timestamp body_time = filter_->body_time(time);
  while (!imu_.empty() && imu_.front().timestamp <= body_time) {
    (void)filter_->propagate(imu_.front());
    imu_.pop_front();
  }
  Result<vision::MsckfUpdateSummary> update = filter_->process_frame(time, frame.observations, rigs_imaged);
  if (!update) {
    frame.reason = update.error().message;
    if (filter_->diverged()) filter_.reset();  // start again from the next still second
    return frame;
  }
  frame.tracking = true;
  frame.update = *update;
  logger()->debug("msckf: frame {:.3f} s: {} tracked, {} of {} features used ({} not triangulated, {} chi-square outliers), {} clones{}",
                  time.seconds(), frame.tracked_features, update->features_used, update->features_offered, update->rejected_triangulation,
                  update->rejected_chi_square, update->clones, update->zero_velocity ? ", standing still" : "");
  zero_velocity_frames_ += update->zero_velocity;
  frame.T_world_body = SE3(filter_->state().R_world_body, filter_->state().position) * T_body_imu_.inverse();
  return frame;
}

}  // namespace hanzo::fusion::pipeline
