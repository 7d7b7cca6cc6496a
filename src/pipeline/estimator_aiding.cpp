// Estimator: the aiding sensors (GNSS with the course-over-ground heading, wheel odometry,
// radar, poses from LiDAR / visual localization).

#include <algorithm>
#include <cmath>

#include "estimator.hpp"
#include "estimator_internal.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/estimate/attitude_models.hpp"
#include "hanzo/fusion/estimate/position_models.hpp"
#include "hanzo/fusion/estimate/radar_ego_velocity.hpp"
#include "hanzo/fusion/estimate/range_models.hpp"
#include "hanzo/fusion/estimate/velocity_models.hpp"

namespace hanzo::fusion::pipeline {
namespace {

constexpr double kZeroVelocitySigma = 0.005;  // m/s
constexpr double kZeroRateSigma = 0.002;      // rad/s
constexpr double kWheelGap = 1.0;             // s: longer gaps between wheel readings are not differenced
constexpr double kWheelMinIntervalFraction = 0.25;  // of the nominal period: closer readings are merged

// The slope of speed over time (m/s^2) and its 1-sigma from the residuals; none with fewer than
// five readings or a span under half a second.
std::optional<std::pair<double, double>> acceleration_of(const std::vector<std::pair<Timestamp, double>>& speeds) {
  if (speeds.size() < 5 || (speeds.back().first - speeds.front().first).seconds() < 0.5) return std::nullopt;
  double mean_t = 0.0, mean_v = 0.0;
  for (const auto& [time, speed] : speeds) {
    mean_t += (time - speeds.front().first).seconds();
    mean_v += speed;
  }
  const double n = static_cast<double>(speeds.size());
  mean_t /= n;
  mean_v /= n;
  double stt = 0.0, stv = 0.0;
  for (const auto& [time, speed] : speeds) {
    const double t = (time - speeds.front().first).seconds() - mean_t;
    stt += t * t;
    stv += t * (speed - mean_v);
  }
  const double slope = stv / stt;
  double residuals = 0.0;
  for (const auto& [time, speed] : speeds) {
    const double t = (time - speeds.front().first).seconds() - mean_t;
    residuals += std::pow(speed - mean_v - slope * t, 2);
  }
  return std::make_pair(slope, std::sqrt(residuals / (n - 2.0) / stt));
}

}  // namespace

using estimate::ErrorCovariance;
using estimate::NavigationState;

EventOutcome Estimator::process_gnss(const Event& event, const msgs::GnssMessage& gnss, UpdateObserver* observer) {
  const SensorSetup& sensor = sensors_[event.sensor];
  if (gnss.fix_type == msgs::GnssFixType::kNoFix) return {false, Rejection::kNoFix};
  if (gnss.fix_type < sensor.config->fusion.min_fix) return {false, Rejection::kWeakFix};
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
  if (heading_pending_ && !align_heading(event.time, antenna_gnss, lever, std::sqrt(std::max(covariance(0, 0), covariance(1, 1)))) &&
      !standing_still()) {
    // Standing still, the position does not depend on the heading: the fix is fused (the course
    // alignment then pivots on the averaged start).
    if (moving_start_) hold_at_fix(antenna_gnss, covariance, lever);
    return {false, Rejection::kHeadingUnknown};
  }
  const estimate::GnssPositionModel model(antenna_gnss, covariance, lever);
  EventOutcome outcome;
  if (gnss_positions_to_backend_) {
    // The backend fuses it: the gate is the filter's, the state stays.
    outcome.fused = update_with(event, model.name(), [&](bool apply_gate) { return filter_->clone()->update(model, apply_gate); }, observer,
                                &outcome.reason, 0, true);
  } else {
    outcome.fused = update(event, model, observer, &outcome.reason);
  }
  if (outcome.fused) {
    const NavigationState after = filter_->state();
    outcome.gnss_fix = FusedGnssFix{"", event.time, antenna_gnss, covariance, lever, SE3(after.R_world_body, after.position),
                                    world_correction_};
  }
  return outcome;
}

bool Estimator::align_heading(Timestamp time, const Eigen::Vector3d& antenna_gnss, const Eigen::Vector3d& lever, double horizontal_sigma) {
  // The recent track for in-motion alignment (its window and a little more).
  const estimate::InMotionAlignmentConfig config;
  recent_fixes_.push_back({time, antenna_gnss, horizontal_sigma});
  keep_recent(recent_fixes_, time, config.window, [](const estimate::GnssTrackPoint& fix) { return fix.time; });
  const NavigationState state = filter_->state();
  if (standing_still()) {
    // The stretch for the course starts where the vehicle last stood.
    course_start_ = CourseStart{antenna_gnss, state.position + state.R_world_body * lever, true};
    return false;
  }
  estimate::InMotionAlignmentInput input{recent_fixes_, recent_imu_, filter_config_.imu_mounting, time, gravity_magnitude_,
                                         wheel_forward_speed_ < 0.0, acceleration_of(recent_wheel_speeds_)};
  const Result<estimate::InMotionAlignment> in_motion = estimate::align_in_motion(input, config);
  if (in_motion) {
    // A static start dead-reckons its track from a known velocity (align_heading_to_course is the
    // more precise then); a moving start, or an estimate whose speed the GNSS track contradicts
    // (a start at constant speed looks still to the IMU), takes the in-motion alignment.
    constexpr double kSpeedMismatch = 1.0;  // m/s, beyond 3 sigma of the GNSS speed
    const double velocity_sigma = in_motion->velocity_sigma;
    const bool contradicted =
        std::abs(state.velocity.head<2>().norm() - in_motion->velocity.head<2>().norm()) > 3.0 * velocity_sigma + kSpeedMismatch;
    if (moving_start_ || contradicted) {
      apply_in_motion_alignment(*in_motion, lever);
      return true;
    }
  }
  return align_heading_to_course(antenna_gnss, state.position + state.R_world_body * lever, horizontal_sigma);
}

void Estimator::hold_at_fix(const Eigen::Vector3d& antenna_gnss, const Eigen::Matrix3d& covariance, const Eigen::Vector3d& lever) {
  NavigationState state = filter_->state();
  state.position = antenna_gnss - state.R_world_body * lever;
  ErrorCovariance P = filter_->covariance();
  P.middleRows<3>(estimate::kPositionIndex).setZero();
  P.middleCols<3>(estimate::kPositionIndex).setZero();
  P.block<3, 3>(estimate::kPositionIndex, estimate::kPositionIndex) = covariance;
  reset_filter(state, P);
}

bool Estimator::standing_still() const {
  constexpr double kRecentWheels = 0.5;  // s
  return !moving_start_ && wheels_still_at_ && (time_ - *wheels_still_at_).seconds() <= kRecentWheels;
}

void Estimator::apply_in_motion_alignment(const estimate::InMotionAlignment& alignment, const Eigen::Vector3d& lever) {
  const NavigationState before = filter_->state();
  const SE3 T_before(before.R_world_body, before.position);
  const SE3 T_after(alignment.R_world_body, alignment.antenna - alignment.R_world_body * lever);
  if (!moving_start_) {
    // The estimate so far was dead-reckoned in a world turned by the heading error: a world
    // correction moves it (and what follows the frontend's world) onto the GNSS track.
    const SE3 correction = T_after * T_before.inverse();
    filter_->apply_world_transform(correction);
    world_correction_ = correction * world_correction_;
  }
  // A moving start's positions were held at the fixes (hold_at_fix), already in the world: the
  // state is set, the world not moved.
  last_keyframe_.reset();  // the motion since it is not known
  NavigationState state = filter_->state();
  state.R_world_body = alignment.R_world_body;
  state.position = T_after.translation();
  state.velocity = alignment.velocity;
  // New uncertainty of position, attitude and velocity; the biases keep theirs (a start that
  // only looked still gets the gyro-bias uncertainty of a moving one).
  const ErrorCovariance previous = filter_->covariance();
  ErrorCovariance P = ErrorCovariance::Zero();
  const double position_sigma = recent_fixes_.back().horizontal_sigma;
  P.block<3, 3>(estimate::kPositionIndex, estimate::kPositionIndex) = Eigen::Matrix3d::Identity() * position_sigma * position_sigma;
  P.block<3, 3>(estimate::kOrientationIndex, estimate::kOrientationIndex) = alignment.orientation_sigma.array().square().matrix().asDiagonal();
  P.block<3, 3>(estimate::kVelocityIndex, estimate::kVelocityIndex) =
      Eigen::Matrix3d::Identity() * alignment.velocity_sigma * alignment.velocity_sigma;
  for (const int index : {estimate::kAccelBiasIndex, estimate::kGyroBiasIndex, estimate::kGravityIndex}) {
    P.block<3, 3>(index, index) = previous.block<3, 3>(index, index);
  }
  for (const int index : {estimate::kWheelScaleIndex, estimate::kGyroYawScaleIndex, estimate::kWheelHeadingDriftIndex}) {
    P(index, index) = previous(index, index);
  }
  P.block<3, 3>(estimate::kGyroBiasIndex, estimate::kGyroBiasIndex) =
      P.block<3, 3>(estimate::kGyroBiasIndex, estimate::kGyroBiasIndex).cwiseMax(Eigen::Matrix3d::Identity() * std::pow(kUnalignedGyroBiasSigma, 2));
  reset_filter(state, P);
  logger()->info("aligned in motion from the GNSS track at {:.1f} m/s: heading {:.1f} deg, roll {:.1f}, pitch {:.1f} deg",
                 alignment.speed, estimate::roll_pitch_yaw(alignment.R_world_body.matrix()).z() * 180.0 / M_PI,
                 estimate::roll_pitch_yaw(alignment.R_world_body.matrix()).x() * 180.0 / M_PI,
                 estimate::roll_pitch_yaw(alignment.R_world_body.matrix()).y() * 180.0 / M_PI);
  heading_pending_ = false;
  moving_start_ = false;
  course_start_.reset();
  recent_fixes_.clear();
  recent_imu_.clear();
  recent_wheel_speeds_.clear();
}

bool Estimator::align_heading_to_course(const Eigen::Vector3d& antenna_gnss, const Eigen::Vector3d& antenna_estimate,
                                        double horizontal_sigma) {
  // Course over ground against the dead-reckoned track over the same stretch: their angle is the
  // heading error. The stretch must be long enough for a course to better than ~3 degrees; the
  // filter refines the heading from there.
  constexpr double kCourseSigma = 0.05;  // rad
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
    const Eigen::Vector3d& pivot = course_start_->averaged ? course_start_->antenna_estimate : course_start_->antenna_gnss;
    const SE3 correction(rotation, pivot - rotation * course_start_->antenna_estimate);
    filter_->apply_world_transform(correction);
    // A correction of the world like the backend's: what follows the Frontend's world (the LiDAR
    // odometry's frame, Frontend::pose_at) follows this one too.
    world_correction_ = correction * world_correction_;
    if (last_keyframe_) last_keyframe_->T_world_body = correction * last_keyframe_->T_world_body;
    logger()->info("heading aligned to the GNSS course over {:.1f} m: corrected by {:.1f} deg", track_gnss.norm(),
                   heading_error * 180.0 / M_PI);
  }
  // The heading is now known to the course's accuracy (not to the configured prior).
  ErrorCovariance P = filter_->covariance();
  constexpr int yaw = estimate::kOrientationIndex + 2;
  P.row(yaw).setZero();
  P.col(yaw).setZero();
  P(yaw, yaw) = course_sigma * course_sigma;
  reset_filter(filter_->state(), P);
  heading_pending_ = false;
  course_start_.reset();
  return true;
}

EventOutcome Estimator::process_wheels(const Event& event, const msgs::WheelOdometryMessage& wheels, UpdateObserver* observer) {
  std::optional<msgs::WheelOdometryMessage>& previous = previous_wheels_[event.sensor];
  const std::optional<msgs::WheelOdometryMessage> before = previous;
  const double dt = before ? (event.time - before->timestamp).seconds() : 0.0;
  // Distances differenced over a sliver of the nominal period turn timestamp jitter into wild
  // speeds (a log stamped to the millisecond with readings 1 ms apart): such a reading is merged,
  // the next one differences over both.
  const double min_interval = kWheelMinIntervalFraction / sensors_[event.sensor].config->rate_hz;
  if (before && dt > 0.0 && dt < min_interval) return {false, Rejection::kMerged};
  previous = wheels;
  previous->timestamp = event.time;  // body clock
  if (!before) return {false, Rejection::kReference};
  if (dt <= 0.0 || dt > kWheelGap) return {false, Rejection::kGap};
  const double left = wheels.left_distance - before->left_distance;
  const double right = wheels.right_distance - before->right_distance;
  wheel_forward_speed_ = 0.5 * (left + right) / dt;
  wheels_still_at_ = left == 0.0 && right == 0.0 ? std::optional<Timestamp>(event.time) : std::nullopt;
  if (heading_pending_) {
    recent_wheel_speeds_.emplace_back(event.time, wheel_forward_speed_);
    keep_recent(recent_wheel_speeds_, event.time, 1.0, [](const std::pair<Timestamp, double>& speed) { return speed.first; });
  }
  // A moving start's velocity is unknown until in-motion alignment: a wheel speed fused into a
  // state with the wrong heading and speed would only pull it further off.
  if (heading_pending_ && moving_start_) return {false, Rejection::kHeadingUnknown};
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
    if (outcome.fused) outcome.velocity = fused_velocity(event, Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity() * kZeroVelocitySigma * kZeroVelocitySigma);
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
  if (outcome.fused && measurement.lateral_constraint && measurement.vertical_constraint) {
    // The wheels' distance per true distance is the state's wheel speed scale.
    const double scale = filter_->state().wheel_speed_scale;
    const Eigen::Vector3d sigmas(measurement.forward_speed_sigma / scale, measurement.lateral_speed_sigma, measurement.lateral_speed_sigma);
    outcome.velocity = fused_velocity(event, Eigen::Vector3d(measurement.forward_speed / scale, 0.0, 0.0), sigmas.cwiseAbs2().asDiagonal());
  }
  if (options.use_yaw_rate || wheel_yaw_rate_needed_) {
    estimate::WheelOdometryMeasurement yaw = measurement;
    yaw.use_speed = yaw.lateral_constraint = yaw.vertical_constraint = false;
    yaw.use_yaw_rate = true;
    std::optional<Rejection> yaw_reason;
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
  if (!ego) return {false, Rejection::kNoEgoVelocity};
  predict_to(event.time);
  const SensorSetup& sensor = sensors_[event.sensor];
  const estimate::GyroReading gyro = gyro_reading();
  const double noise = sensor.config->fusion.velocity_noise;
  const Eigen::Matrix3d covariance = ego->covariance + noise * noise * Eigen::Matrix3d::Identity();
  const estimate::SensorVelocityModel model(ego->velocity_sensor, covariance, sensor.T_body_sensor, gyro);
  EventOutcome outcome;
  outcome.fused = update(event, model, observer, &outcome.reason);
  if (outcome.fused) outcome.velocity = fused_velocity(event, ego->velocity_sensor, covariance);
  return outcome;
}

EventOutcome Estimator::process_range(const Event& event, const msgs::RangeMessage& range, UpdateObserver* observer) {
  // A beam more than this far from straight down does not see the floor (or sees it at a
  // slant too steep to trust); readings that disagree this long mean the floor moved.
  constexpr double kMaxBeamTiltRad = 30.0 * M_PI / 180.0;
  constexpr double kFloorStepSeconds = 1.0;
  // The reading's noise when the message gives none (1 cm + 1 % of the range, an ultrasonic
  // module's), and the floor's unevenness (2 cm).
  constexpr double kFloorUnevenness = 0.02;
  // Another sensor measured the horizontal motion this recently.
  constexpr double kHorizontalAidingSeconds = 2.0;
  if (!std::isfinite(range.range)) return {false, Rejection::kNotFused};  // nothing in range, or too near
  // With the IMU alone, height updates pull on the tilt and accelerometer-bias estimates they are
  // correlated with, and nothing horizontal checks what that does: the horizontal estimate drifts
  // faster (bench/RESULTS.md, 2026-12-04). So the height is fused only while another sensor
  // (GNSS, LiDAR, camera, wheels, radar) constrains the horizontal motion.
  const bool horizontally_aided = std::any_of(sensors_.begin(), sensors_.end(), [&](const SensorSetup& other) {
    const size_t index = static_cast<size_t>(&other - sensors_.data());
    const config::SensorModality modality = other.config->modality;
    return modality != config::SensorModality::kImu && modality != config::SensorModality::kRange && !last_fused_[index].is_zero() &&
           (event.time - last_fused_[index]).seconds() <= kHorizontalAidingSeconds;
  });
  if (!horizontally_aided) return {false, Rejection::kNotFused};
  predict_to(event.time);
  const SE3& T_body_sensor = sensors_[event.sensor].T_body_sensor;
  const NavigationState state = filter_->state();
  const Eigen::Vector3d beam_world = state.R_world_body * (T_body_sensor.rotation() * Eigen::Vector3d::UnitX());
  if (-beam_world.z() < std::cos(kMaxBeamTiltRad)) return {false, Rejection::kNotFused};
  const double sensor_z = (state.position + state.R_world_body * T_body_sensor.translation()).z();
  std::optional<double>& floor = floor_heights_[event.sensor];
  Timestamp& gated_since = gated_since_[2 * event.sensor];
  if (!floor || (!gated_since.is_zero() && (event.time - gated_since).seconds() > kFloorStepSeconds)) {
    // The floor under the cone's ray nearest to straight down.
    const double slant = std::max(0.0, std::acos(std::min(1.0, -beam_world.z())) - 0.5 * range.field_of_view);
    const double new_floor = sensor_z - range.range * std::cos(slant);
    if (floor) logger()->info("sensor '{}': the floor moved by {:.2f} m", sensors_[event.sensor].config->name, new_floor - *floor);
    floor = new_floor;
    gated_since = Timestamp();
    return {true, std::nullopt};
  }
  const double reading_sigma = 0.01 + 0.01 * range.range;
  const double variance = (range.variance > 0.0F ? range.variance : reading_sigma * reading_sigma) + kFloorUnevenness * kFloorUnevenness;
  const estimate::FloorRangeModel model(range.range, variance, *floor, T_body_sensor, 0.5 * range.field_of_view);
  EventOutcome outcome;
  outcome.fused = update(event, model, observer, &outcome.reason);
  return outcome;
}

FusedVelocity Estimator::fused_velocity(const Event& event, const Eigen::Vector3d& velocity_sensor, const Eigen::Matrix3d& covariance) const {
  const estimate::GyroReading gyro = gyro_reading();
  const Eigen::Vector3d angular_rate_body = gyro.R_body_imu * (gyro.angular_velocity - filter_->state().gyro_bias);
  return FusedVelocity{"", event.time, velocity_sensor, covariance, sensors_[event.sensor].T_body_sensor, angular_rate_body};
}

EventOutcome Estimator::process_pose(const Event& event, const PoseMeasurement& pose, UpdateObserver* observer) {
  if (pose.in_map) return process_map_pose(event, pose, observer);
  predict_to(event.time);
  const estimate::PoseModel model(pose.T_world_sensor, pose.covariance, sensors_[event.sensor].T_body_sensor);
  EventOutcome outcome;
  outcome.fused = update(event, model, observer, &outcome.reason, 0, pose.gated);
  return outcome;
}

EventOutcome Estimator::process_map_pose(const Event& event, const PoseMeasurement& pose, UpdateObserver* observer) {
  predict_to(event.time);
  const SE3& T_body_sensor = sensors_[event.sensor].T_body_sensor;
  std::optional<MapLink>& link = map_links_[event.sensor];
  if (!link) {
    // The first pose defines the frame: the map is where the estimate puts the sensor now.
    const SE3 T_body_map = T_body_sensor * pose.T_world_sensor.inverse();
    const estimate::NavigationState state = filter_->state();
    link = MapLink{filter_->add_map_frame(T_body_map), SE3(state.R_world_body, state.position) * T_body_map};
    return {true, std::nullopt};
  }
  EventOutcome outcome;
  if (link->frame) {
    const estimate::MapPoseModel model(*link->frame, pose.T_world_sensor, pose.covariance, T_body_sensor);
    outcome.fused = update_with(event, model.name(), [&](bool apply_gate) { return filter_->update_map_pose(model, apply_gate); },
                                observer, &outcome.reason, 0, pose.gated);
  } else {
    // The covariance's position block from the map's axes to the world's.
    Eigen::Matrix<double, 6, 6> J = Eigen::Matrix<double, 6, 6>::Identity();
    J.topLeftCorner<3, 3>() = link->T_world_map.rotation().matrix();
    const estimate::PoseModel model(link->T_world_map * pose.T_world_sensor, J * pose.covariance * J.transpose(), T_body_sensor);
    outcome.fused = update(event, model, observer, &outcome.reason, 0, pose.gated);
  }
  return outcome;
}

std::optional<SE3> Estimator::map_frame(size_t sensor) const {
  const std::optional<MapLink>& link = map_links_[sensor];
  if (!link) return std::nullopt;
  return link->frame ? filter_->map_frame(*link->frame) : std::optional<SE3>(link->T_world_map);
}


}  // namespace hanzo::fusion::pipeline
