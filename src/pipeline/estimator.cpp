#include "estimator.hpp"
#include "estimator_internal.hpp"

#include <cmath>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/estimate/attitude_models.hpp"
#include "hanzo/fusion/estimate/error_state_ekf.hpp"
#include "hanzo/fusion/estimate/particle_filter.hpp"
#include "hanzo/fusion/estimate/unscented_kalman_filter.hpp"
#include "hanzo/fusion/estimate/static_alignment.hpp"
#include "hanzo/fusion/estimate/velocity_models.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using config::SensorModality;
using estimate::ErrorCovariance;
using estimate::NavigationState;

// Initial uncertainty of the states the spec's configuration does not cover.
constexpr double kInitialAccelBiasSigma = 0.1;      // m/s^2
constexpr double kInitialGyroBiasSigma = 0.01;      // rad/s, after static alignment
constexpr double kMovingStartVelocitySigma = 5.0;   // m/s: a moving start's speed comes from wheels / GNSS
constexpr double kResumeVelocitySigma = 0.1;        // m/s: a resumed state's velocity (the filter's own estimate)
constexpr double kInitialGravitySigma = 0.02;       // m/s^2, vertical (magnitude)
constexpr double kHorizontalGravitySigma = 1e-6;    // m/s^2: ENU's up is the gravity direction
constexpr double kGravityMagnitudeSigma = 0.001;    // m/s^2, pseudo-measurement at 1 Hz
// The wheel speed scale (navigation_state.hpp): an uncalibrated wheel radius is off by a few
// percent; load and tyre pressure move it slowly.
constexpr double kInitialWheelScaleSigma = 0.02;
constexpr double kWheelScaleRandomWalk = 1e-4;      // 1/sqrt(s)
// The gyro's yaw-rate scale: MEMS gyros are specified to 0.5-2 %; temperature moves it slowly.
constexpr double kInitialGyroYawScaleSigma = 0.01;
constexpr double kGyroYawScaleRandomWalk = 1e-5;    // 1/sqrt(s)
// The wheels' heading drift: wheel radii 0.15 % apart (a calibrated drive) on a 0.5 m axle drift
// 0.003 rad/m, uncalibrated ones several times more (learnt wherever the speed varies); tyre
// pressure and load move it over hours (a faster walk lets it absorb the gyro bias's error).
constexpr double kInitialWheelHeadingDriftSigma = 0.003;  // rad/m
constexpr double kWheelHeadingDriftRandomWalk = 1e-6;    // rad/m/sqrt(s)
constexpr double kPlanarHeightSigma = 0.005;        // m
constexpr double kPlanarVerticalSpeedSigma = 0.01;  // m/s
constexpr double kPlanarLevelSigma = 0.01;          // rad: roll, pitch of a planar robot without an IMU
constexpr double kLevelPriorSigma = 0.1;            // rad: roll, pitch of anything else without an IMU
// Without an IMU (motion model, see estimator.hpp).
constexpr double kMotionModelOrientationNoise = 0.01;  // rad/sqrt(s): attitude jitter besides the turn rate
constexpr double kMotionModelAccelBiasSigma = 1e-4;    // m/s^2: the virtual accelerometer has no bias
constexpr double kMotionModelAccelBiasWalk = 1e-6;     // m/s^2/sqrt(s)
constexpr double kMotionModelInitialRateSigma = 0.5;   // rad/s: the start may be in a turn
constexpr double kMotionModelStep = 0.01;              // s: the longest single prediction step

estimate::ImuSample imu_sample(Timestamp time, const msgs::ImuMessage& imu) {
  return {time, imu.angular_velocity, imu.linear_acceleration};
}

std::unique_ptr<estimate::Filter> make_filter(const estimate::FilterConfig& config, const config::FrontendConfig& frontend) {
  switch (frontend.type) {
    case config::FrontendType::kUkf:
      return std::make_unique<estimate::UnscentedKalmanFilter>(config, estimate::UkfConfig{frontend.ukf.alpha, frontend.ukf.beta, frontend.ukf.kappa});
    case config::FrontendType::kParticle: {
      const config::ParticleFilterSettings& settings = frontend.particle_filter;
      return std::make_unique<estimate::ParticleFilter>(
          config, estimate::ParticleFilterConfig{settings.particles, settings.resample_threshold, settings.seed});
    }
    case config::FrontendType::kEkf:
    case config::FrontendType::kMsckf: break;  // the EKF; the cameras go through the MSCKF (camera_odometry.hpp)
  }
  return std::make_unique<estimate::ErrorStateEkf>(config);
}

}  // namespace

bool fused_before(const Event& a, const Event& b) {
  if (a.time != b.time) return a.time < b.time;
  if (a.is_imu != b.is_imu) return a.is_imu;
  return a.sequence < b.sequence;
}

Estimator::Estimator(const config::FusionConfig& config, std::vector<SensorSetup> sensors, std::optional<size_t> imu_sensor)
    : frontend_(config.frontend),
      sensors_(std::move(sensors)),
      imu_sensor_(imu_sensor),
      spike_filter_(estimate::ImuSpikeFilterConfig{}, estimate::ImuNoise{}) {
  const config::CovarianceConfig& covariance = frontend_.covariance;
  if (imu_sensor_) {
    filter_config_.imu_mounting = estimate::ImuMounting::from_transform(sensors_[*imu_sensor_].T_body_sensor);
    filter_config_.imu_noise = {covariance.process_noise_accel, covariance.process_noise_gyro, covariance.accel_bias_random_walk,
                                covariance.gyro_bias_random_walk, 1.0 / sensors_[*imu_sensor_].config->rate_hz};
  } else {
    // Densities (sample interval 1 s): see the class comment.
    const config::MotionModelSettings& motion = frontend_.motion_model;
    filter_config_.imu_noise = {motion.acceleration_noise, kMotionModelOrientationNoise, kMotionModelAccelBiasWalk,
                                motion.angular_acceleration_noise, 1.0};
  }
  // The wheel speed scale is estimated where something measures distance besides the wheels
  // (GNSS, LiDAR or camera poses); against the IMU alone it is not observable, only drift.
  const auto configured = [this](SensorModality modality) {
    return std::any_of(sensors_.begin(), sensors_.end(), [modality](const SensorSetup& s) { return s.config->modality == modality; });
  };
  estimate_wheel_scale_ = configured(SensorModality::kWheelOdometry) &&
                (configured(SensorModality::kGnss) || configured(SensorModality::kLidar) || configured(SensorModality::kCamera));
  if (estimate_wheel_scale_) filter_config_.imu_noise.wheel_scale_random_walk = kWheelScaleRandomWalk;
  // With an IMU and the wheels' yaw rate fused, the gyro measures the wheels' heading drift
  // whenever the car drives straight; the gyro's yaw scale needs a heading reference besides.
  estimate_wheel_heading_drift_ = imu_sensor_ && std::any_of(sensors_.begin(), sensors_.end(), [](const SensorSetup& s) {
                                    return s.config->modality == SensorModality::kWheelOdometry && s.config->fusion.use_yaw_rate;
                                  });
  estimate_gyro_yaw_scale_ = estimate_wheel_heading_drift_ && estimate_wheel_scale_;
  if (estimate_wheel_heading_drift_) filter_config_.imu_noise.wheel_heading_drift_random_walk = kWheelHeadingDriftRandomWalk;
  if (estimate_gyro_yaw_scale_) filter_config_.imu_noise.gyro_yaw_scale_random_walk = kGyroYawScaleRandomWalk;
  filter_config_.gate_probability = frontend_.gate_probability;
  filter_ = make_filter(filter_config_, frontend_);
  spike_filter_ = estimate::ImuSpikeFilter(estimate::ImuSpikeFilterConfig{}, filter_config_.imu_noise);
  previous_wheels_.resize(sensors_.size());
  last_fused_.resize(sensors_.size());
  const bool has_gnss = configured(SensorModality::kGnss);
  // With GNSS the world is ENU, and unless the IMU reports its heading nothing says where the
  // body faces in it: GNSS fixes wait until the GNSS track gives the heading (align_heading).
  const bool imu_heading = imu_sensor_ && sensors_[*imu_sensor_].config->fusion.use_orientation[2];
  heading_pending_ = has_gnss && !imu_heading && !frontend_.initial_yaw;
  gated_since_.resize(2 * sensors_.size());
  map_links_.resize(sensors_.size());
  floor_heights_.resize(sensors_.size());
  wheel_yaw_rate_needed_ = !imu_sensor_ && std::none_of(sensors_.begin(), sensors_.end(), [](const SensorSetup& s) {
    return s.config->modality == SensorModality::kLidar || s.config->modality == SensorModality::kCamera;
  });
}

Estimator::Estimator(const Estimator& other)
    : frontend_(other.frontend_),
      sensors_(other.sensors_),
      imu_sensor_(other.imu_sensor_),
      filter_config_(other.filter_config_),
      filter_(other.filter_->clone()),
      spike_filter_(other.spike_filter_),
      initialized_(other.initialized_),
      time_(other.time_),
      last_imu_(other.last_imu_),
      alignment_samples_(other.alignment_samples_),
      previous_wheels_(other.previous_wheels_),
      last_fused_(other.last_fused_),
      gated_since_(other.gated_since_),
      enu_(other.enu_),
      gnss_before_initialization_(other.gnss_before_initialization_),
      wheels_moved_before_initialization_(other.wheels_moved_before_initialization_),
      heading_pending_(other.heading_pending_),
      gnss_positions_to_backend_(other.gnss_positions_to_backend_),
      wheel_yaw_rate_needed_(other.wheel_yaw_rate_needed_),
      estimate_wheel_scale_(other.estimate_wheel_scale_),
      estimate_gyro_yaw_scale_(other.estimate_gyro_yaw_scale_),
      estimate_wheel_heading_drift_(other.estimate_wheel_heading_drift_),
      course_start_(other.course_start_),
      moving_start_(other.moving_start_),
      recent_fixes_(other.recent_fixes_),
      recent_imu_(other.recent_imu_),
      recent_wheel_speeds_(other.recent_wheel_speeds_),
      wheel_forward_speed_(other.wheel_forward_speed_),
      wheels_still_at_(other.wheels_still_at_),
      gravity_magnitude_(other.gravity_magnitude_),
      last_keyframe_(other.last_keyframe_),
      planar_height_(other.planar_height_),
      last_gravity_update_(other.last_gravity_update_),
      world_correction_(other.world_correction_),
      map_links_(other.map_links_),
      floor_heights_(other.floor_heights_) {}

Estimator& Estimator::operator=(const Estimator& other) {
  if (this != &other) *this = Estimator(other);
  return *this;
}

Estimator::~Estimator() = default;

estimate::GyroReading Estimator::gyro_reading() const {
  estimate::GyroReading gyro;
  gyro.R_body_imu = filter_config_.imu_mounting.R_body_imu;
  if (last_imu_) gyro.angular_velocity = last_imu_->angular_velocity;
  return gyro;
}

EventOutcome Estimator::process(const Event& event, UpdateObserver* observer) {
  if (!imu_sensor_) {
    if (!initialized_ && !std::holds_alternative<WorldCorrection>(event.payload)) initialize_without_imu(event);
    if (!initialized_) return {false, Rejection::kBeforeInitialization};
  }
  if (!initialized_ && !event.is_imu) {
    const auto* message = std::get_if<msgs::SensorMessage>(&event.payload);
    const auto* gnss = message ? std::get_if<msgs::GnssMessage>(message) : nullptr;
    if (gnss && frontend_.datum && gnss->fix_type >= sensors_[event.sensor].config->fusion.min_fix) {
      gnss_before_initialization_.emplace(event.sensor, *gnss);
    }
    if (const auto* wheels = message ? std::get_if<msgs::WheelOdometryMessage>(message) : nullptr) {
      std::optional<msgs::WheelOdometryMessage>& previous = previous_wheels_[event.sensor];
      if (previous && (wheels->left_distance != previous->left_distance || wheels->right_distance != previous->right_distance)) {
        wheels_moved_before_initialization_ = true;
      }
      previous = *wheels;
      previous->timestamp = event.time;
    }
    return {false, Rejection::kBeforeInitialization};
  }
  EventOutcome outcome;
  if (const auto* pose = std::get_if<PoseMeasurement>(&event.payload)) {
    outcome = process_pose(event, *pose, observer);
  } else if (const auto* velocity = std::get_if<VelocityMeasurement>(&event.payload)) {
    predict_to(event.time);
    const estimate::SensorVelocityModel model(velocity->velocity_sensor, velocity->covariance, sensors_[event.sensor].T_body_sensor,
                                              gyro_reading());
    outcome.fused = update(event, model, observer, &outcome.reason);
  } else if (const auto* correction = std::get_if<WorldCorrection>(&event.payload)) {
    predict_to(event.time);
    filter_->apply_world_transform(correction->T_correction);
    world_correction_ = correction->T_correction * world_correction_;
    if (last_keyframe_) last_keyframe_->T_world_body = correction->T_correction * last_keyframe_->T_world_body;
    for (std::optional<MapLink>& link : map_links_) {
      if (link && !link->frame) link->T_world_map = correction->T_correction * link->T_world_map;
    }
    // A floor moves with the world: its point under the body, moved.
    const Eigen::Vector3d position = filter_->state().position;
    for (std::optional<double>& floor : floor_heights_) {
      if (floor) floor = (correction->T_correction * Eigen::Vector3d(position.x(), position.y(), *floor)).z();
    }
    return {true, std::nullopt};
  } else if (std::holds_alternative<MotionTick>(event.payload)) {
    predict_to(event.time);
    outcome = {true, std::nullopt};
  } else {
    const auto& message = std::get<msgs::SensorMessage>(event.payload);
    if (const auto* imu = std::get_if<msgs::ImuMessage>(&message)) {
      outcome = process_imu(event, *imu, observer);
    } else if (const auto* gnss = std::get_if<msgs::GnssMessage>(&message)) {
      outcome = process_gnss(event, *gnss, observer);
    } else if (const auto* wheels = std::get_if<msgs::WheelOdometryMessage>(&message)) {
      outcome = process_wheels(event, *wheels, observer);
    } else if (const auto* radar = std::get_if<msgs::RadarMessage>(&message)) {
      outcome = process_radar(event, *radar, observer);
    } else if (const auto* range = std::get_if<msgs::RangeMessage>(&message)) {
      outcome = process_range(event, *range, observer);
    } else {
      outcome = {false, Rejection::kNotFused};
    }
  }
  if (!imu_sensor_ && outcome.fused) {
    // The motion model's counterparts of what IMU events do.
    apply_constraints(event);
    outcome.keyframe = maybe_keyframe(event.time);
  }
  return outcome;
}

estimate::ImuSample Estimator::motion_model_sample() const {
  // Constant velocity in the body's axes (a turning vehicle's velocity turns with it): the
  // centripetal acceleration w x v_body besides the gravity reaction; w = -gyro bias.
  const NavigationState state = filter_->state();
  const Eigen::Vector3d angular_velocity = -state.gyro_bias;
  const Eigen::Vector3d velocity_body = state.R_world_body.inverse() * state.velocity;
  return {time_, Eigen::Vector3d::Zero(),
          state.R_world_body.inverse() * (-state.gravity) + angular_velocity.cross(velocity_body) + state.accel_bias};
}

void Estimator::predict_to(Timestamp t) {
  if (!imu_sensor_) {
    while (time_ < t) {
      const Timestamp next = std::min(t, time_ + Duration::from_seconds(kMotionModelStep));
      filter_->predict(motion_model_sample(), (next - time_).seconds());
      time_ = next;
    }
    last_imu_ = motion_model_sample();
    return;
  }
  if (t <= time_ || !last_imu_) return;
  filter_->predict(*last_imu_, (t - time_).seconds());
  time_ = t;
}

bool Estimator::update(const Event& event, const estimate::MeasurementModel& model, UpdateObserver* observer,
                       std::optional<Rejection>* reason, int channel, bool gated) {
  return update_with(event, model.name(), [&](bool apply_gate) { return filter_->update(model, apply_gate); }, observer, reason, channel,
                     gated);
}

bool Estimator::update_with(const Event& event, std::string_view model_name, const std::function<estimate::UpdateOutcome(bool)>& apply,
                            UpdateObserver* observer, std::optional<Rejection>* reason, int channel, bool gated) {
  Timestamp& gated_since = gated_since_[2 * event.sensor + static_cast<size_t>(channel)];
  // A sensor whose every update has been gated for gate_recovery seconds is fused without the
  // gate: by then the estimate (a bad start, a misconfigured noise) is the likelier culprit, and
  // gating it out forever would lock the filter out of its own aiding sensors.
  const double recovery = frontend_.gate_recovery_s;
  const bool locked_out = recovery > 0.0 && !gated_since.is_zero() && (event.time - gated_since).seconds() > recovery;
  const estimate::UpdateOutcome outcome = apply(gated && !locked_out);
  if (observer != nullptr) observer->on_update({event.sensor, model_name, event.time, outcome});
  if (outcome.status == estimate::UpdateStatus::kRejectedByGate && gated_since.is_zero()) gated_since = event.time;
  if (outcome.status != estimate::UpdateStatus::kApplied) {
    if (reason != nullptr) {
      *reason = outcome.status == estimate::UpdateStatus::kRejectedByGate ? Rejection::kGated : Rejection::kNumericalFailure;
    }
    return false;
  }
  if (gated && locked_out && outcome.mahalanobis_squared > outcome.gate) {
    logger()->warn("sensor '{}' disagreed with the estimate for {:.1f} s: fused without the gate (d^2 = {:.1f})",
                   sensors_[event.sensor].config->name, (event.time - gated_since).seconds(), outcome.mahalanobis_squared);
  }
  if (outcome.mahalanobis_squared <= outcome.gate) gated_since = Timestamp();
  last_fused_[event.sensor] = event.time;
  return true;
}

void Estimator::initialize(const Event& event, const msgs::ImuMessage& imu) {
  const config::SensorFusionOptions& options = sensors_[event.sensor].config->fusion;
  const estimate::ImuMounting& mounting = filter_config_.imu_mounting;
  const config::CovarianceConfig& covariance = frontend_.covariance;
  NavigationState state;
  if (resume_state_) {
    // A session restarted elsewhere: its last state, carried to this sample at constant velocity.
    const double elapsed = (event.time - resume_state_->timestamp).seconds();
    state.timestamp = event.time;
    state.R_world_body = SO3::from_quaternion_normalized(resume_state_->T_world_body.orientation.normalized());
    state.position = resume_state_->T_world_body.position + resume_state_->velocity * elapsed;
    state.velocity = resume_state_->velocity;
    state.gravity = Eigen::Vector3d(0.0, 0.0, -gravity_magnitude_);
    const Eigen::Matrix3d position_covariance = resume_state_->pose_covariance
                                                    ? Eigen::Matrix3d(resume_state_->pose_covariance->topLeftCorner<3, 3>())
                                                    : Eigen::Matrix3d(covariance.initial_position.array().square().matrix().asDiagonal());
    heading_pending_ = false;
    resume_state_.reset();
    start(state, position_covariance, Eigen::Vector3d::Constant(kResumeVelocitySigma), kInitialAccelBiasSigma, kUnalignedGyroBiasSigma);
    logger()->info("frontend resumed at t = {:.3f} s from the state at {:.3f} s", event.time.seconds(), (event.time.seconds() - elapsed));
    return;
  }
  double gyro_bias_sigma = kInitialGyroBiasSigma;
  Eigen::Vector3d velocity_sigma = covariance.initial_velocity;

  if (imu.orientation && options.use_orientation[0] && options.use_orientation[1]) {
    // The IMU reports its attitude: start from it (heading too when selected).
    const SO3 R_world_body =
        SO3::from_quaternion_normalized(*imu.orientation) * mounting.R_body_imu.inverse();
    const Eigen::Vector3d rpy = estimate::roll_pitch_yaw(R_world_body.matrix());
    const double yaw = options.use_orientation[2] ? rpy.z() : frontend_.initial_yaw.value_or(0.0);
    state.R_world_body = estimate::rotation_from_roll_pitch_yaw(rpy.x(), rpy.y(), yaw);
    gyro_bias_sigma = kUnalignedGyroBiasSigma;
  } else {
    alignment_samples_.push_back(imu_sample(event.time, imu));
    if ((event.time - alignment_samples_.front().timestamp).seconds() < frontend_.static_alignment_s) return;
    Result<estimate::StaticAlignment> alignment =
        wheels_moved_before_initialization_ ? Result<estimate::StaticAlignment>(Error("the wheels turned"))
                                            : estimate::align_static(alignment_samples_, mounting, frontend_.initial_yaw.value_or(0.0));
    if (!alignment) {
      // Moving start: the mean specific force is still the best guess of "up".
      logger()->warn("initializing while moving ({}); roll and pitch from the mean specific force", alignment.error().message);
      estimate::StaticAlignmentConfig permissive;
      permissive.max_accel_std = std::numeric_limits<double>::infinity();
      permissive.max_gyro_std = std::numeric_limits<double>::infinity();
      alignment = estimate::align_static(alignment_samples_, mounting, frontend_.initial_yaw.value_or(0.0), permissive);
      gyro_bias_sigma = kUnalignedGyroBiasSigma;
      velocity_sigma = velocity_sigma.cwiseMax(kMovingStartVelocitySigma);
      moving_start_ = true;
      if (!alignment) return;  // not even gravity visible yet: keep collecting
      alignment->gyro_bias.setZero();
    }
    state.R_world_body = alignment->R_world_body;
    state.gyro_bias = alignment->gyro_bias;
    gravity_magnitude_ = alignment->gravity_magnitude;
    alignment_samples_.clear();
    alignment_samples_.shrink_to_fit();
  }
  state.gravity = Eigen::Vector3d(0.0, 0.0, -gravity_magnitude_);
  state.timestamp = event.time;
  // With a configured datum the world frame is fixed: start at the latest GNSS fix.
  Eigen::Matrix3d position_covariance = covariance.initial_position.array().square().matrix().asDiagonal();
  if (gnss_before_initialization_) {
    const auto& [gnss_sensor, fix] = *gnss_before_initialization_;
    enu_ = EnuFrame::create(*frontend_.datum).value();
    const Eigen::Vector3d antenna = enu_->to_enu(fix.geodetic());
    state.position = antenna - state.R_world_body * sensors_[gnss_sensor].T_body_sensor.translation();
    position_covariance = fix.position_covariance.value_or(default_gnss_covariance(fix.fix_type));
    gnss_before_initialization_.reset();
  }

  start(state, position_covariance, velocity_sigma, kInitialAccelBiasSigma, gyro_bias_sigma);
  logger()->info("frontend initialized at t = {:.3f} s (roll {:.2f}, pitch {:.2f} deg)", event.time.seconds(),
                 estimate::roll_pitch_yaw(state.R_world_body.matrix()).x() * 180.0 / M_PI,
                 estimate::roll_pitch_yaw(state.R_world_body.matrix()).y() * 180.0 / M_PI);
}

void Estimator::start(const NavigationState& state, const Eigen::Matrix3d& position_covariance, const Eigen::Vector3d& velocity_sigma,
                      double accel_bias_sigma, double gyro_bias_sigma) {
  ErrorCovariance P = ErrorCovariance::Zero();
  const auto set_block = [&P](int index, const Eigen::Vector3d& sigmas) {
    P.block<3, 3>(index, index) = sigmas.array().square().matrix().asDiagonal();
  };
  P.block<3, 3>(estimate::kPositionIndex, estimate::kPositionIndex) = position_covariance;
  set_block(estimate::kOrientationIndex, frontend_.covariance.initial_orientation);
  set_block(estimate::kVelocityIndex, velocity_sigma);
  set_block(estimate::kAccelBiasIndex, Eigen::Vector3d::Constant(accel_bias_sigma));
  set_block(estimate::kGyroBiasIndex, Eigen::Vector3d::Constant(gyro_bias_sigma));
  set_block(estimate::kGravityIndex, Eigen::Vector3d(kHorizontalGravitySigma, kHorizontalGravitySigma, kInitialGravitySigma));
  if (estimate_wheel_scale_) P(estimate::kWheelScaleIndex, estimate::kWheelScaleIndex) = kInitialWheelScaleSigma * kInitialWheelScaleSigma;
  if (estimate_gyro_yaw_scale_) {
    P(estimate::kGyroYawScaleIndex, estimate::kGyroYawScaleIndex) = kInitialGyroYawScaleSigma * kInitialGyroYawScaleSigma;
  }
  if (estimate_wheel_heading_drift_) {
    P(estimate::kWheelHeadingDriftIndex, estimate::kWheelHeadingDriftIndex) = kInitialWheelHeadingDriftSigma * kInitialWheelHeadingDriftSigma;
  }
  reset_filter(state, P);
  initialized_ = true;
  time_ = state.timestamp;
  last_gravity_update_ = state.timestamp;
  planar_height_ = state.position.z();
}

void Estimator::reset_filter(const NavigationState& state, const ErrorCovariance& covariance) {
  filter_->reset(state, covariance);
  for (std::optional<MapLink>& link : map_links_) link.reset();
  for (std::optional<double>& floor : floor_heights_) floor.reset();
}

void Estimator::initialize_without_imu(const Event& event) {
  const config::CovarianceConfig& covariance = frontend_.covariance;
  NavigationState state;
  state.timestamp = event.time;
  state.R_world_body = estimate::rotation_from_roll_pitch_yaw(0.0, 0.0, frontend_.initial_yaw.value_or(0.0));
  state.gravity = Eigen::Vector3d(0.0, 0.0, -gravity_magnitude_);
  Eigen::Matrix3d position_covariance = covariance.initial_position.array().square().matrix().asDiagonal();
  const auto* message = std::get_if<msgs::SensorMessage>(&event.payload);
  const auto* gnss = message ? std::get_if<msgs::GnssMessage>(message) : nullptr;
  if (gnss && frontend_.datum && gnss->fix_type >= sensors_[event.sensor].config->fusion.min_fix) {
    // With a configured datum the world frame is fixed: start at the fix.
    enu_ = EnuFrame::create(*frontend_.datum).value();
    state.position = enu_->to_enu(gnss->geodetic()) - sensors_[event.sensor].T_body_sensor.translation();
    position_covariance = gnss->position_covariance.value_or(default_gnss_covariance(gnss->fix_type));
  }
  start(state, position_covariance, covariance.initial_velocity.cwiseMax(kMovingStartVelocitySigma), kMotionModelAccelBiasSigma,
        kMotionModelInitialRateSigma);
  last_imu_ = motion_model_sample();
  logger()->info("frontend initialized at t = {:.3f} s without an IMU: level, constant-velocity motion model", event.time.seconds());
}

EventOutcome Estimator::process_imu(const Event& event, const msgs::ImuMessage& imu, UpdateObserver* observer) {
  const estimate::ImuSample sample = imu_sample(event.time, imu);
  if (!spike_filter_.accept(sample)) return {false, Rejection::kSpike};
  if (!initialized_) {
    initialize(event, imu);
    if (!initialized_) return {false, Rejection::kAligning};
    last_imu_ = sample;
    last_fused_[event.sensor] = event.time;
    return {true, std::nullopt};
  }
  predict_to(event.time);
  last_imu_ = sample;
  last_fused_[event.sensor] = event.time;
  if (heading_pending_) {
    // In-motion alignment's IMU window (a few seconds; the GNSS track's mean time is in it).
    recent_imu_.push_back(sample);
    keep_recent(recent_imu_, event.time, estimate::InMotionAlignmentConfig{}.window,
                [](const estimate::ImuSample& s) { return s.timestamp; });
  }

  const config::SensorFusionOptions& options = sensors_[event.sensor].config->fusion;
  EventOutcome outcome{true, std::nullopt};
  if (imu.orientation && (options.use_orientation[0] || options.use_orientation[1] || options.use_orientation[2])) {
    const Eigen::Matrix3d covariance = imu.orientation_covariance.value_or(
        Eigen::Matrix3d::Identity() * options.orientation_noise * options.orientation_noise);
    const estimate::ImuAttitudeModel model(SO3::from_quaternion_normalized(*imu.orientation), covariance,
                                           filter_config_.imu_mounting.R_body_imu, options.use_orientation);
    if (!model.usable()) {
      outcome.reason = Rejection::kGimbalLock;
    } else {
      update(event, model, observer, &outcome.reason);
    }
  }
  apply_constraints(event);
  outcome.keyframe = maybe_keyframe(event.time);
  return outcome;
}

void Estimator::apply_constraints(const Event& event) {
  if (frontend_.planar) {
    filter_->update(estimate::PlanarMotionModel(planar_height_, kPlanarHeightSigma, kPlanarVerticalSpeedSigma));
  }
  if (!imu_sensor_) {
    // Without an IMU nothing measures roll and pitch (the motion model's accelerometer reads the
    // estimate's own gravity); unheld, they drift, and a wheel speed turns into a wrong ground
    // speed through the tilt. Held level: firmly on a planar robot, loosely otherwise (a 3D
    // LiDAR's poses measure them far better where they apply).
    const double sigma = frontend_.planar ? kPlanarLevelSigma : kLevelPriorSigma;
    const Eigen::Matrix3d R = filter_->state().R_world_body.matrix();
    const SO3 level = SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), std::atan2(R(1, 0), R(0, 0)));
    const estimate::ImuAttitudeModel model(level, Eigen::Matrix3d::Identity() * sigma * sigma, SO3(), {true, true, false});
    if (model.usable()) filter_->update(model);
  }
  if ((event.time - last_gravity_update_).seconds() >= 1.0) {
    filter_->update(estimate::GravityMagnitudeModel(gravity_magnitude_, kGravityMagnitudeSigma));
    last_gravity_update_ = event.time;
  }
}

}  // namespace hanzo::fusion::pipeline
