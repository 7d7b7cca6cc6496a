#include "msckf_odometry.hpp"

#include <fmt/format.h>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/estimate/static_alignment.hpp"

namespace hanzo::fusion::pipeline {
namespace {

constexpr double kAlignmentSeconds = 1.0;  // still IMU used to start the filter
constexpr size_t kMaxBufferedSamples = 20000;

}  // namespace

Result<std::unique_ptr<MsckfOdometry>> MsckfOdometry::create(const std::vector<MsckfCameraSetup>& cameras, cv::Size image_size,
                                                             const SE3& T_body_imu, const estimate::ImuNoise& imu_noise) {
  if (cameras.empty() || cameras.size() > 2) return Error(fmt::format("MsckfOdometry: {} cameras; one or two are supported", cameras.size()));
  std::unique_ptr<vision::FeatureTracker> tracker;
  if (cameras.size() == 2) {
    HANZO_ASSIGN_OR_RETURN(tracker, vision::FeatureTracker::create_stereo(cameras[0].camera, cameras[1].camera,
                                                                          cameras[0].T_body_camera.inverse() * cameras[1].T_body_camera, image_size));
  } else {
    HANZO_ASSIGN_OR_RETURN(tracker, vision::FeatureTracker::create(cameras[0].camera, image_size));
  }
  std::vector<vision::MsckfCamera> msckf_cameras;
  for (const MsckfCameraSetup& setup : cameras) msckf_cameras.push_back({T_body_imu.inverse() * setup.T_body_camera, setup.camera.fx});
  return std::unique_ptr<MsckfOdometry>(new MsckfOdometry(std::move(tracker), std::move(msckf_cameras), T_body_imu, imu_noise));
}

MsckfOdometry::MsckfOdometry(std::unique_ptr<vision::FeatureTracker> tracker, std::vector<vision::MsckfCamera> cameras, const SE3& T_body_imu,
                             const estimate::ImuNoise& imu_noise)
    : tracker_(std::move(tracker)), cameras_(std::move(cameras)), T_body_imu_(T_body_imu), imu_noise_(imu_noise) {}

void MsckfOdometry::add_imu(const estimate::ImuSample& sample) {
  if (!imu_.empty() && sample.timestamp <= imu_.back().timestamp) return;
  if (filter_ && sample.timestamp <= filter_->state().timestamp) return;
  imu_.push_back(sample);
  if (!filter_) {
    while (!imu_.empty() && (sample.timestamp - imu_.front().timestamp).seconds() > 2.0 * kAlignmentSeconds) imu_.pop_front();
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
  if (!aligned) return fmt::format("initializing: waiting for a still start ({})", aligned.error().message);
  estimate::NavigationState state;
  state.timestamp = still.back().timestamp;
  state.R_world_body = aligned->R_world_body;
  state.gyro_bias = aligned->gyro_bias;
  state.gravity = Eigen::Vector3d(0.0, 0.0, -aligned->gravity_magnitude);
  Eigen::Matrix<double, 15, 1> sigma;
  sigma << Eigen::Vector3d::Constant(1e-3), Eigen::Vector3d(0.02, 0.02, 1e-3), Eigen::Vector3d::Constant(0.02),
      Eigen::Vector3d::Constant(0.1), Eigen::Vector3d::Constant(0.005);
  vision::MsckfConfig config;
  config.imu_noise = imu_noise_;
  Result<vision::Msckf> filter = vision::Msckf::create(config, cameras_, state, sigma.array().square().matrix().asDiagonal().toDenseMatrix());
  if (!filter) return "initializing: " + filter.error().message;
  filter_.emplace(std::move(filter).value());
  (void)filter_->propagate(still.back());
  while (!imu_.empty() && imu_.front().timestamp <= state.timestamp) imu_.pop_front();
  return std::nullopt;
}

Result<MsckfOdometry::Frame> MsckfOdometry::track(Timestamp time, const cv::Mat& left, const cv::Mat& right) {
  vision::TrackedFrame tracked;
  HANZO_ASSIGN_OR_RETURN(tracked, right.empty() ? tracker_->track(left) : tracker_->track(left, right));
  Frame frame;
  frame.tracked_features = tracked.tracked;
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
  Result<vision::MsckfUpdateSummary> update = filter_->process_frame(time, tracked.observations);
  if (!update) {
    frame.reason = update.error().message;
    if (filter_->diverged()) filter_.reset();  // start again from the next still second
    return frame;
  }
  frame.tracking = true;
  frame.update = *update;
  logger()->debug("msckf: frame {:.3f} s: {} tracked, {} of {} features used ({} not triangulated, {} chi-square outliers), {} clones{}",
                  time.seconds(), tracked.tracked, update->features_used, update->features_offered, update->rejected_triangulation,
                  update->rejected_chi_square, update->clones, update->zero_velocity ? ", standing still" : "");
  zero_velocity_frames_ += update->zero_velocity;
  frame.T_world_body = SE3(filter_->state().R_world_body, filter_->state().position) * T_body_imu_.inverse();
  return frame;
}

}  // namespace hanzo::fusion::pipeline
