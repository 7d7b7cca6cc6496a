#include "estimator.hpp"

#include <cmath>

#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/estimate/attitude_models.hpp"
#include "hanzo/fusion/estimate/error_state_ekf.hpp"
#include "hanzo/fusion/estimate/particle_filter.hpp"
#include "hanzo/fusion/estimate/unscented_kalman_filter.hpp"
#include "hanzo/fusion/estimate/position_models.hpp"
#include "hanzo/fusion/estimate/radar_ego_velocity.hpp"
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
constexpr double kUnalignedGyroBiasSigma = 0.05;    // rad/s, when not aligned (moving start)
constexpr double kMovingStartVelocitySigma = 5.0;   // m/s: a moving start's speed comes from wheels / GNSS
constexpr double kInitialGravitySigma = 0.02;       // m/s^2, vertical (magnitude)
constexpr double kHorizontalGravitySigma = 1e-6;    // m/s^2: ENU's up is the gravity direction
constexpr double kGravityMagnitudeSigma = 0.001;    // m/s^2, pseudo-measurement at 1 Hz
constexpr double kPlanarHeightSigma = 0.005;        // m
constexpr double kPlanarVerticalSpeedSigma = 0.01;  // m/s
constexpr double kZeroVelocitySigma = 0.005;        // m/s
constexpr double kZeroRateSigma = 0.002;            // rad/s
constexpr double kWheelGap = 1.0;                   // s: longer gaps between wheel readings are not differenced

// Default GNSS position noise per fix type when a message has no covariance (1 sigma, m).
Eigen::Matrix3d default_gnss_covariance(msgs::GnssFixType fix) {
  double horizontal = 2.5;
  double vertical = 5.0;
  switch (fix) {
    case msgs::GnssFixType::kFix2d: horizontal = 5.0; vertical = 50.0; break;
    case msgs::GnssFixType::kRtkFloat: horizontal = 0.5; vertical = 1.0; break;
    case msgs::GnssFixType::kRtkFixed: horizontal = 0.02; vertical = 0.05; break;
    default: break;
  }
  return Eigen::Vector3d(horizontal * horizontal, horizontal * horizontal, vertical * vertical).asDiagonal();
}

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
    case config::FrontendType::kEkf: break;
  }
  return std::make_unique<estimate::ErrorStateEkf>(config);
}

}  // namespace

bool fused_before(const Event& a, const Event& b) {
  if (a.time != b.time) return a.time < b.time;
  if (a.is_imu != b.is_imu) return a.is_imu;
  return a.sequence < b.sequence;
}

Estimator::Estimator(const config::FusionConfig& config, std::vector<SensorSetup> sensors, size_t imu_sensor)
    : frontend_(config.frontend),
      sensors_(std::move(sensors)),
      imu_sensor_(imu_sensor),
      spike_filter_(estimate::ImuSpikeFilterConfig{}, estimate::ImuNoise{}) {
  const config::CovarianceConfig& covariance = frontend_.covariance;
  filter_config_.imu_mounting = estimate::ImuMounting::from_transform(sensors_[imu_sensor_].T_body_sensor);
  filter_config_.imu_noise = {covariance.process_noise_accel, covariance.process_noise_gyro, covariance.accel_bias_random_walk,
                              covariance.gyro_bias_random_walk, 1.0 / sensors_[imu_sensor_].config->rate_hz};
  filter_config_.gate_probability = frontend_.gate_probability;
  filter_ = make_filter(filter_config_, frontend_);
  spike_filter_ = estimate::ImuSpikeFilter(estimate::ImuSpikeFilterConfig{}, filter_config_.imu_noise);
  previous_wheels_.resize(sensors_.size());
  last_fused_.resize(sensors_.size());
  const bool has_gnss = std::any_of(sensors_.begin(), sensors_.end(),
                                    [](const SensorSetup& s) { return s.config->modality == SensorModality::kGnss; });
  // The configured yaw uncertainty says whether the start heading is known: above ~30 degrees
  // it is not, and GNSS fixes wait until the course over ground gives it.
  constexpr double kUnknownYawSigma = 0.5;  // rad
  heading_pending_ = has_gnss && !sensors_[imu_sensor_].config->fusion.use_orientation[2] &&
                     frontend_.covariance.initial_orientation.z() > kUnknownYawSigma;
  gated_since_.resize(2 * sensors_.size());
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
      course_start_(other.course_start_),
      gravity_magnitude_(other.gravity_magnitude_),
      last_keyframe_(other.last_keyframe_),
      planar_height_(other.planar_height_),
      last_gravity_update_(other.last_gravity_update_) {}

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
    return {false, "before_initialization"};
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
    if (last_keyframe_) last_keyframe_->T_world_body = correction->T_correction * last_keyframe_->T_world_body;
    outcome = {true, {}};
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
    } else {
      outcome = {false, "not_fused"};
    }
  }
  return outcome;
}

void Estimator::predict_to(Timestamp t) {
  if (t <= time_ || !last_imu_) return;
  filter_->predict(*last_imu_, (t - time_).seconds());
  time_ = t;
}

bool Estimator::update(const Event& event, const estimate::MeasurementModel& model, UpdateObserver* observer,
                       std::string_view* reason, int channel) {
  Timestamp& gated_since = gated_since_[2 * event.sensor + static_cast<size_t>(channel)];
  // A sensor whose every update has been gated for gate_recovery seconds is fused without the
  // gate: by then the estimate (a bad start, a misconfigured noise) is the likelier culprit, and
  // gating it out forever would lock the filter out of its own aiding sensors.
  const double recovery = frontend_.gate_recovery_s;
  const bool locked_out = recovery > 0.0 && !gated_since.is_zero() && (event.time - gated_since).seconds() > recovery;
  const estimate::UpdateOutcome outcome = filter_->update(model, !locked_out);
  if (observer != nullptr) observer->on_update({event.sensor, model.name(), event.time, outcome});
  if (outcome.status == estimate::UpdateStatus::kRejectedByGate && gated_since.is_zero()) gated_since = event.time;
  if (outcome.status != estimate::UpdateStatus::kApplied) {
    if (reason != nullptr) *reason = to_string(outcome.status);
    return false;
  }
  if (locked_out && outcome.mahalanobis_squared > outcome.gate) {
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
  double gyro_bias_sigma = kInitialGyroBiasSigma;
  Eigen::Vector3d velocity_sigma = covariance.initial_velocity;

  if (imu.orientation && options.use_orientation[0] && options.use_orientation[1]) {
    // The IMU reports its attitude: start from it (heading too when selected).
    const SO3 R_world_body =
        SO3::from_quaternion_normalized(*imu.orientation) * mounting.R_body_imu.inverse();
    const Eigen::Vector3d rpy = estimate::roll_pitch_yaw(R_world_body.matrix());
    state.R_world_body = estimate::rotation_from_roll_pitch_yaw(rpy.x(), rpy.y(), options.use_orientation[2] ? rpy.z() : 0.0);
    gyro_bias_sigma = kUnalignedGyroBiasSigma;
  } else {
    alignment_samples_.push_back(imu_sample(event.time, imu));
    if ((event.time - alignment_samples_.front().timestamp).seconds() < frontend_.static_alignment_s) return;
    Result<estimate::StaticAlignment> alignment =
        wheels_moved_before_initialization_ ? Result<estimate::StaticAlignment>(Error("the wheels turned"))
                                            : estimate::align_static(alignment_samples_, mounting, 0.0);
    if (!alignment) {
      // Moving start: the mean specific force is still the best guess of "up".
      logger()->warn("initializing while moving ({}); roll and pitch from the mean specific force", alignment.error().message);
      estimate::StaticAlignmentConfig permissive;
      permissive.max_accel_std = std::numeric_limits<double>::infinity();
      permissive.max_gyro_std = std::numeric_limits<double>::infinity();
      alignment = estimate::align_static(alignment_samples_, mounting, 0.0, permissive);
      gyro_bias_sigma = kUnalignedGyroBiasSigma;
      velocity_sigma = velocity_sigma.cwiseMax(kMovingStartVelocitySigma);
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

  ErrorCovariance P = ErrorCovariance::Zero();
  const auto set_block = [&P](int index, const Eigen::Vector3d& sigmas) {
    P.block<3, 3>(index, index) = sigmas.array().square().matrix().asDiagonal();
  };
  P.block<3, 3>(estimate::kPositionIndex, estimate::kPositionIndex) = position_covariance;
  set_block(estimate::kOrientationIndex, covariance.initial_orientation);
  set_block(estimate::kVelocityIndex, velocity_sigma);
  set_block(estimate::kAccelBiasIndex, Eigen::Vector3d::Constant(kInitialAccelBiasSigma));
  set_block(estimate::kGyroBiasIndex, Eigen::Vector3d::Constant(gyro_bias_sigma));
  set_block(estimate::kGravityIndex, Eigen::Vector3d(kHorizontalGravitySigma, kHorizontalGravitySigma, kInitialGravitySigma));
  filter_->reset(state, P);
  initialized_ = true;
  time_ = event.time;
  last_gravity_update_ = event.time;
  planar_height_ = state.position.z();
  logger()->info("frontend initialized at t = {:.3f} s (roll {:.2f}, pitch {:.2f} deg)", event.time.seconds(),
                 estimate::roll_pitch_yaw(state.R_world_body.matrix()).x() * 180.0 / M_PI,
                 estimate::roll_pitch_yaw(state.R_world_body.matrix()).y() * 180.0 / M_PI);
}

EventOutcome Estimator::process_imu(const Event& event, const msgs::ImuMessage& imu, UpdateObserver* observer) {
  const estimate::ImuSample sample = imu_sample(event.time, imu);
  if (!spike_filter_.accept(sample)) return {false, "spike"};
  if (!initialized_) {
    initialize(event, imu);
    if (!initialized_) return {false, "aligning"};
    last_imu_ = sample;
    last_fused_[event.sensor] = event.time;
    return {true, {}};
  }
  predict_to(event.time);
  last_imu_ = sample;
  last_fused_[event.sensor] = event.time;

  const config::SensorFusionOptions& options = sensors_[event.sensor].config->fusion;
  EventOutcome outcome{true, {}};
  if (imu.orientation && (options.use_orientation[0] || options.use_orientation[1] || options.use_orientation[2])) {
    const Eigen::Matrix3d covariance = imu.orientation_covariance.value_or(
        Eigen::Matrix3d::Identity() * options.orientation_noise * options.orientation_noise);
    const estimate::ImuAttitudeModel model(SO3::from_quaternion_normalized(*imu.orientation), covariance,
                                           filter_config_.imu_mounting.R_body_imu, options.use_orientation);
    if (!model.usable()) {
      outcome.reason = "gimbal_lock";
    } else {
      update(event, model, observer, &outcome.reason);
    }
  }
  apply_constraints(event);
  outcome.keyframe = maybe_keyframe(event.time);
  return outcome;
}

std::optional<msgs::Keyframe> Estimator::maybe_keyframe(Timestamp time) {
  if (last_keyframe_ && (time - last_keyframe_->time).seconds() < frontend_.keyframe_interval_s) return std::nullopt;
  const NavigationState state = filter_->state();
  const ErrorCovariance P = filter_->covariance();
  const SE3 T_world_body(state.R_world_body, state.position);
  msgs::Keyframe keyframe;
  keyframe.keyframe_id = last_keyframe_ ? last_keyframe_->id + 1 : 0;
  keyframe.timestamp = time;
  keyframe.T_world_body = msgs::Pose::from_se3(T_world_body);
  keyframe.velocity = state.velocity;
  keyframe.pose_covariance = P.topLeftCorner<6, 6>();
  if (last_keyframe_) {
    // The previous keyframe's pose as later measurements corrected it (smoothed clone), and the
    // joint covariance of the two poses' errors.
    const std::optional<estimate::PoseClone> clone = filter_->pose_clone();
    SE3 T_world_previous = last_keyframe_->T_world_body;
    Eigen::Matrix<double, 12, 12> joint = Eigen::Matrix<double, 12, 12>::Zero();
    joint.topLeftCorner<6, 6>() = last_keyframe_->covariance;
    if (clone) {
      T_world_previous = SE3(T_world_previous.rotation() * SO3::exp(clone->correction.tail<3>()),
                             T_world_previous.translation() + clone->correction.head<3>());
      joint.topLeftCorner<6, 6>() = clone->covariance;
      joint.topRightCorner<6, 6>() = clone->cross.leftCols<6>();
      joint.bottomLeftCorner<6, 6>() = clone->cross.leftCols<6>().transpose();
    }
    joint.bottomRightCorner<6, 6>() = P.topLeftCorner<6, 6>();
    // T_rel = T_a^-1 T_b, tangent (rho, phi) with T_rel_true = T_rel Exp(rho, phi); errors of a
    // and b are (position world, orientation body):
    //   d rho = R_b^T dp_b - R_rel^T R_a^T dp_a + R_rel^T [p_rel]x dtheta_a,  d phi = dtheta_b - R_rel^T dtheta_a.
    const SE3 T_relative = T_world_previous.inverse() * T_world_body;
    const Eigen::Matrix3d R_a = T_world_previous.rotation().matrix();
    const Eigen::Matrix3d R_b = state.R_world_body.matrix();
    const Eigen::Matrix3d R_rel_t = T_relative.rotation().matrix().transpose();
    Eigen::Matrix<double, 6, 12> J = Eigen::Matrix<double, 6, 12>::Zero();
    J.block<3, 3>(0, 0) = -R_rel_t * R_a.transpose();
    J.block<3, 3>(0, 3) = R_rel_t * SO3::hat(T_relative.translation());
    J.block<3, 3>(0, 6) = R_b.transpose();
    J.block<3, 3>(3, 3) = -R_rel_t;
    J.block<3, 3>(3, 9) = Eigen::Matrix3d::Identity();
    keyframe.previous_keyframe_id = last_keyframe_->id;
    keyframe.T_previous_current = msgs::Pose::from_se3(T_relative);
    msgs::Matrix6d relative = J * joint * J.transpose();
    keyframe.relative_covariance = 0.5 * (relative + relative.transpose());
  }
  filter_->clone_pose();
  last_keyframe_ = KeyframeAnchor{keyframe.keyframe_id, time, T_world_body, P.topLeftCorner<6, 6>()};
  return keyframe;
}

void Estimator::apply_constraints(const Event& event) {
  if (frontend_.planar) {
    filter_->update(estimate::PlanarMotionModel(planar_height_, kPlanarHeightSigma, kPlanarVerticalSpeedSigma));
  }
  if ((event.time - last_gravity_update_).seconds() >= 1.0) {
    filter_->update(estimate::GravityMagnitudeModel(gravity_magnitude_, kGravityMagnitudeSigma));
    last_gravity_update_ = event.time;
  }
}

EventOutcome Estimator::process_gnss(const Event& event, const msgs::GnssMessage& gnss, UpdateObserver* observer) {
  const SensorSetup& sensor = sensors_[event.sensor];
  if (gnss.fix_type == msgs::GnssFixType::kNoFix) return {false, "no_fix"};
  if (gnss.fix_type < sensor.config->fusion.min_fix) return {false, "weak_fix"};
  predict_to(event.time);
  const NavigationState state = filter_->state();
  const Eigen::Vector3d& lever = sensor.T_body_sensor.translation();
  if (!enu_) {
    if (frontend_.datum) {
      enu_ = EnuFrame::create(*frontend_.datum).value();
    } else {
      // The first fix defines the world frame so that it lands where the estimate has the
      // antenna now (the world origin is where the frontend started).
      const EnuFrame at_fix = EnuFrame::create(gnss.geodetic()).value();
      const Eigen::Vector3d antenna = state.position + state.R_world_body * lever;
      enu_ = EnuFrame::create(at_fix.to_geodetic(-antenna)).value();
      logger()->info("GNSS datum set from the first fix: lat {:.8f}, lon {:.8f}, alt {:.3f}", enu_->datum().latitude_deg,
                     enu_->datum().longitude_deg, enu_->datum().altitude_m);
    }
  }
  Eigen::Matrix3d covariance = gnss.position_covariance.value_or(default_gnss_covariance(gnss.fix_type));
  if (!(covariance.diagonal().array() > 0.0).all()) covariance = default_gnss_covariance(gnss.fix_type);
  const Eigen::Vector3d antenna_gnss = enu_->to_enu(gnss.geodetic());
  if (heading_pending_ &&
      !align_heading_to_course(antenna_gnss, state.position + state.R_world_body * lever, std::sqrt(std::max(covariance(0, 0), covariance(1, 1))))) {
    return {false, "heading_unknown"};
  }
  const estimate::GnssPositionModel model(antenna_gnss, covariance, lever);
  EventOutcome outcome;
  outcome.fused = update(event, model, observer, &outcome.reason);
  return outcome;
}

bool Estimator::align_heading_to_course(const Eigen::Vector3d& antenna_gnss, const Eigen::Vector3d& antenna_estimate,
                                        double horizontal_sigma) {
  // Course over ground against the dead-reckoned track over the same stretch: their angle is the
  // heading error. The stretch must be long enough for a course to better than ~0.6 degrees.
  constexpr double kCourseSigma = 0.01;  // rad
  constexpr double kMinimumStretch = 10.0;  // m
  if (!course_start_) {
    course_start_ = CourseStart{antenna_gnss, antenna_estimate};
    return false;
  }
  const Eigen::Vector2d track_gnss = (antenna_gnss - course_start_->antenna_gnss).head<2>();
  const Eigen::Vector2d track_estimate = (antenna_estimate - course_start_->antenna_estimate).head<2>();
  const double needed = std::max(kMinimumStretch, std::sqrt(2.0) * horizontal_sigma / kCourseSigma);
  if (track_gnss.norm() < needed || track_estimate.norm() < 0.5 * track_gnss.norm()) return false;
  const double heading_error = std::atan2(track_estimate.x() * track_gnss.y() - track_estimate.y() * track_gnss.x(),
                                          track_estimate.dot(track_gnss));
  const double course_sigma = std::sqrt(2.0) * horizontal_sigma / track_gnss.norm();
  if (std::abs(heading_error) > 2.0 * course_sigma) {
    // Rotate the estimate about the stretch's start onto the GNSS track.
    const SO3 rotation = SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), heading_error);
    const SE3 correction(rotation, course_start_->antenna_gnss - rotation * course_start_->antenna_estimate);
    filter_->apply_world_transform(correction);
    if (last_keyframe_) last_keyframe_->T_world_body = correction * last_keyframe_->T_world_body;
    logger()->info("heading aligned to the GNSS course over {:.1f} m: corrected by {:.1f} deg", track_gnss.norm(),
                   heading_error * 180.0 / M_PI);
  }
  // The heading is now known to the course's accuracy (not to the configured prior).
  ErrorCovariance P = filter_->covariance();
  constexpr int yaw = estimate::kOrientationIndex + 2;
  P.row(yaw).setZero();
  P.col(yaw).setZero();
  P(yaw, yaw) = 4.0 * course_sigma * course_sigma;
  filter_->reset(filter_->state(), P);
  heading_pending_ = false;
  course_start_.reset();
  return true;
}

EventOutcome Estimator::process_wheels(const Event& event, const msgs::WheelOdometryMessage& wheels, UpdateObserver* observer) {
  std::optional<msgs::WheelOdometryMessage>& previous = previous_wheels_[event.sensor];
  const std::optional<msgs::WheelOdometryMessage> before = previous;
  previous = wheels;
  previous->timestamp = event.time;  // body clock
  if (!before) return {false, "reference"};
  const double dt = (event.time - before->timestamp).seconds();
  if (dt <= 0.0 || dt > kWheelGap) return {false, "gap"};
  const double left = wheels.left_distance - before->left_distance;
  const double right = wheels.right_distance - before->right_distance;
  predict_to(event.time);

  const SensorSetup& sensor = sensors_[event.sensor];
  const config::SensorFusionOptions& options = sensor.config->fusion;
  const estimate::GyroReading gyro = gyro_reading();
  EventOutcome outcome;
  if (frontend_.zero_velocity_updates && left == 0.0 && right == 0.0) {
    // The rate residual uses one gyro sample: its white noise adds to the constraint's.
    const double rate_sigma = std::hypot(kZeroRateSigma, filter_config_.imu_noise.process_noise_gyro);
    const estimate::ZeroVelocityModel model(kZeroVelocitySigma, rate_sigma, true, gyro);
    outcome.fused = update(event, model, observer, &outcome.reason);
    outcome.zero_velocity_update = outcome.fused;
    return outcome;
  }
  estimate::WheelOdometryMeasurement measurement;
  // The differenced distances give the mean speed over the interval, i.e. the speed at its
  // middle; the IMU's forward acceleration carries it to the end of the interval, where the
  // measurement is fused (without this, accelerating vehicles see a lag of dt/2).
  double forward_acceleration = 0.0;
  if (last_imu_) {
    const NavigationState state = filter_->state();
    const estimate::BodyMotion motion = estimate::body_motion(state, *last_imu_, filter_config_.imu_mounting);
    const Eigen::Vector3d acceleration_body = motion.specific_force + state.R_world_body.inverse() * state.gravity;
    forward_acceleration = (sensor.T_body_sensor.rotation().inverse() * acceleration_body).x();
  }
  measurement.forward_speed = 0.5 * (left + right) / dt + 0.5 * dt * forward_acceleration;
  measurement.yaw_rate = (right - left) / (wheels.wheel_separation * dt);
  measurement.forward_speed_sigma = options.speed_noise;
  measurement.yaw_rate_sigma = options.yaw_rate_noise;
  measurement.lateral_speed_sigma = options.lateral_speed_noise;
  measurement.lateral_constraint = options.non_holonomic;
  measurement.vertical_constraint = options.non_holonomic && !frontend_.planar;
  // Speed (with the non-holonomic constraint) and yaw rate are gated separately: a slipping
  // wheel shows first in the yaw rate, which the gyro contradicts, while the speed may still
  // be good.
  measurement.use_yaw_rate = false;
  outcome.fused = update(event, estimate::WheelOdometryModel(measurement, sensor.T_body_sensor, gyro), observer, &outcome.reason);
  if (options.use_yaw_rate) {
    estimate::WheelOdometryMeasurement yaw = measurement;
    yaw.use_speed = yaw.lateral_constraint = yaw.vertical_constraint = false;
    yaw.use_yaw_rate = true;
    std::string_view yaw_reason;
    if (update(event, estimate::WheelOdometryModel(yaw, sensor.T_body_sensor, gyro), observer, &yaw_reason, 1)) {
      outcome.fused = true;
    } else if (outcome.fused) {
      outcome.fused = false;
      outcome.reason = yaw_reason;  // counted by its worst part
    }
  }
  return outcome;
}

EventOutcome Estimator::process_radar(const Event& event, const msgs::RadarMessage& radar, UpdateObserver* observer) {
  // Seeded by the scan's time: the same scan always gives the same estimate.
  const Result<estimate::RadarEgoVelocity> ego =
      estimate::estimate_radar_ego_velocity(radar.targets, {}, static_cast<uint64_t>(event.time.nanoseconds()));
  if (!ego) return {false, "no_ego_velocity"};
  predict_to(event.time);
  const SensorSetup& sensor = sensors_[event.sensor];
  const estimate::GyroReading gyro = gyro_reading();
  const double noise = sensor.config->fusion.velocity_noise;
  const estimate::SensorVelocityModel model(ego->velocity_sensor, ego->covariance + noise * noise * Eigen::Matrix3d::Identity(),
                                            sensor.T_body_sensor, gyro);
  EventOutcome outcome;
  outcome.fused = update(event, model, observer, &outcome.reason);
  return outcome;
}

EventOutcome Estimator::process_pose(const Event& event, const PoseMeasurement& pose, UpdateObserver* observer) {
  predict_to(event.time);
  const estimate::PoseModel model(pose.T_world_sensor, pose.covariance, sensors_[event.sensor].T_body_sensor);
  EventOutcome outcome;
  outcome.fused = update(event, model, observer, &outcome.reason);
  return outcome;
}

}  // namespace hanzo::fusion::pipeline
