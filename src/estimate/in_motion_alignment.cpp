#include "hanzo/fusion/estimate/in_motion_alignment.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Dense>
#include <fmt/format.h>

#include "hanzo/fusion/estimate/static_alignment.hpp"

namespace hanzo::fusion::estimate {
namespace {

// The antenna track p(tau) = c0 + c1 tau + c2 tau^2 around the fixes' mean time (a line when
// there are too few fixes for a curve to be more than noise).
struct TrackFit {
  Timestamp mean_time;
  Eigen::Vector3d position, velocity, acceleration;  // at mean_time
  double velocity_sigma = 0.0;                        // per axis
  double acceleration_sigma = std::numeric_limits<double>::infinity();
  Eigen::Vector3d at(double tau) const { return position + velocity * tau + 0.5 * acceleration * tau * tau; }
};

TrackFit fit_track(const std::vector<GnssTrackPoint>& fixes) {
  constexpr size_t kFixesForCurve = 5;
  const int terms = fixes.size() >= kFixesForCurve ? 3 : 2;
  double mean_seconds = 0.0;
  for (const GnssTrackPoint& fix : fixes) mean_seconds += (fix.time - fixes.front().time).seconds();
  mean_seconds /= static_cast<double>(fixes.size());
  TrackFit fit;
  fit.mean_time = fixes.front().time + Duration::from_seconds(mean_seconds);
  Eigen::MatrixXd A(fixes.size(), terms);
  Eigen::MatrixXd b(fixes.size(), 3);
  for (size_t i = 0; i < fixes.size(); ++i) {
    const double tau = (fixes[i].time - fit.mean_time).seconds();
    const double weight = 1.0 / fixes[i].horizontal_sigma;  // rows whitened
    A(static_cast<Eigen::Index>(i), 0) = weight;
    A(static_cast<Eigen::Index>(i), 1) = weight * tau;
    if (terms == 3) A(static_cast<Eigen::Index>(i), 2) = weight * tau * tau;
    b.row(static_cast<Eigen::Index>(i)) = weight * fixes[i].antenna.transpose();
  }
  const Eigen::MatrixXd normal = A.transpose() * A;
  const Eigen::MatrixXd coefficients = normal.ldlt().solve(A.transpose() * b);
  const Eigen::MatrixXd covariance = normal.inverse();  // of the coefficients, per axis
  fit.position = coefficients.row(0).transpose();
  fit.velocity = coefficients.row(1).transpose();
  fit.velocity_sigma = std::sqrt(covariance(1, 1));
  fit.acceleration.setZero();
  if (terms == 3) {
    fit.acceleration = 2.0 * coefficients.row(2).transpose();
    fit.acceleration_sigma = 2.0 * std::sqrt(covariance(2, 2));
  }
  return fit;
}

}  // namespace

Eigen::Vector2d roll_pitch_from_specific_force(const Eigen::Vector3d& f_body, const Eigen::Vector3d& f_world, double yaw) {
  // Ry(pitch) Rx(roll) f_body = u = Rz(yaw)^T f_world. Rx keeps x and turns (y, z): with
  // f_y = r sin(alpha), f_z = r cos(alpha), its y is r sin(alpha - roll) = u_y. Ry then turns
  // (x, z) by pitch onto (u_x, u_z).
  const Eigen::Vector3d u = SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), yaw).inverse() * f_world.normalized() * f_body.norm();
  const double r = std::hypot(f_body.y(), f_body.z());
  const double alpha = std::atan2(f_body.y(), f_body.z());
  const double roll = alpha - std::asin(std::clamp(u.y() / std::max(r, 1e-9), -1.0, 1.0));
  const double z_after_roll = r * std::cos(alpha - roll);
  const double pitch = std::atan2(u.x(), u.z()) - std::atan2(f_body.x(), z_after_roll);
  return {std::remainder(roll, 2.0 * M_PI), std::remainder(pitch, 2.0 * M_PI)};
}

Result<InMotionAlignment> align_in_motion(const InMotionAlignmentInput& input, const InMotionAlignmentConfig& config) {
  const std::vector<GnssTrackPoint>& all_fixes = input.fixes;
  const std::vector<ImuSample>& imu = input.imu;
  const ImuMounting& mounting = input.mounting;
  const Timestamp now = input.now;
  const double gravity_magnitude = input.gravity_magnitude;
  if (all_fixes.empty()) return Error("in-motion alignment: no GNSS fix");
  std::vector<GnssTrackPoint> fixes;
  for (const GnssTrackPoint& fix : all_fixes) {
    if ((all_fixes.back().time - fix.time).seconds() <= config.window) fixes.push_back(fix);
  }
  if (fixes.size() < 3) return Error(fmt::format("in-motion alignment: {} GNSS fixes in the last {} s, needs 3", fixes.size(), config.window));
  const double span = (fixes.back().time - fixes.front().time).seconds();
  if (span < config.min_span) return Error(fmt::format("in-motion alignment: the GNSS track spans {:.2f} s, needs {} s", span, config.min_span));
  const TrackFit fit = fit_track(fixes);
  const double speed = fit.velocity.head<2>().norm();
  constexpr double kFullWindow = 0.9;  // of the window: the track is as long as it gets
  const double speed_to_noise = span >= kFullWindow * config.window ? config.min_speed_to_noise_full_window : config.min_speed_to_noise;
  if (speed < config.min_speed || speed < speed_to_noise * fit.velocity_sigma) {
    return Error(fmt::format("in-motion alignment: speed {:.2f} m/s (1-sigma {:.2f}) is too low for a course", speed, fit.velocity_sigma));
  }

  // The IMU: heading change since the track's mean time, and the recent specific force and rate.
  double heading_change = 0.0;
  Eigen::Vector3d specific_force = Eigen::Vector3d::Zero();
  double yaw_rate = 0.0;
  int recent = 0;
  for (size_t i = 0; i < imu.size(); ++i) {
    const Eigen::Vector3d rate_body = mounting.R_body_imu * imu[i].angular_velocity;
    if (i > 0 && imu[i].timestamp > fit.mean_time && imu[i].timestamp <= now) {
      const Timestamp from = std::max(imu[i - 1].timestamp, fit.mean_time);
      heading_change += rate_body.z() * (imu[i].timestamp - from).seconds();
    }
    if ((now - imu[i].timestamp).seconds() <= config.specific_force_window && imu[i].timestamp <= now) {
      specific_force += mounting.R_body_imu * imu[i].linear_acceleration;
      yaw_rate += rate_body.z();
      ++recent;
    }
  }
  if (recent == 0) return Error(fmt::format("in-motion alignment: no IMU sample in the last {} s", config.specific_force_window));
  specific_force /= recent;
  yaw_rate /= recent;

  const double dt = (now - fit.mean_time).seconds();
  const bool acceleration_known = fit.acceleration_sigma <= config.max_acceleration_sigma;
  const double course_mid = std::atan2(fit.velocity.y(), fit.velocity.x());
  const Eigen::Vector2d direction_mid(std::cos(course_mid), std::sin(course_mid));
  double along_track = acceleration_known ? fit.acceleration.head<2>().dot(direction_mid) : 0.0;
  double acceleration_sigma = acceleration_known ? fit.acceleration_sigma : config.unknown_acceleration;
  if (input.forward_acceleration && input.forward_acceleration->second < acceleration_sigma) {
    // Along the track is forward, or backward when reversing.
    along_track = input.reversing ? -input.forward_acceleration->first : input.forward_acceleration->first;
    acceleration_sigma = input.forward_acceleration->second;
  }
  const double course = course_mid + heading_change;
  const Eigen::Vector2d direction(std::cos(course), std::sin(course));
  const double speed_now = std::max(0.0, speed + along_track * dt);

  InMotionAlignment alignment;
  alignment.speed = speed;
  alignment.velocity << speed_now * direction, fit.velocity.z() + (acceleration_known ? fit.acceleration.z() * dt : 0.0);
  alignment.antenna = fit.at(dt);
  // The vehicle's acceleration now: along the track and towards the turn's centre (w x v).
  Eigen::Vector3d acceleration = Eigen::Vector3d::Zero();
  acceleration.head<2>() = along_track * direction + yaw_rate * speed_now * Eigen::Vector2d(-direction.y(), direction.x());
  const double heading = course + (input.reversing ? M_PI : 0.0);
  const Eigen::Vector2d roll_pitch =
      roll_pitch_from_specific_force(specific_force, acceleration + Eigen::Vector3d(0.0, 0.0, gravity_magnitude), heading);
  alignment.R_world_body = rotation_from_roll_pitch_yaw(roll_pitch.x(), roll_pitch.y(), heading);
  // Roll rests on the lateral (centripetal) acceleration, known from the gyro and the speed;
  // pitch on the along-track one, as well known as the fit or the caller's forward acceleration.
  constexpr double kAccelBiasTilt = 0.01;  // rad: an uncalibrated accelerometer bias of ~0.1 m/s^2
  const double roll_sigma = std::hypot(kAccelBiasTilt, std::abs(yaw_rate) * fit.velocity_sigma / gravity_magnitude);
  const double pitch_sigma = std::hypot(kAccelBiasTilt, acceleration_sigma / gravity_magnitude);
  alignment.orientation_sigma = Eigen::Vector3d(roll_sigma, pitch_sigma, std::hypot(fit.velocity_sigma / speed, config.slip_sigma));
  alignment.velocity_sigma = std::hypot(fit.velocity_sigma, acceleration_sigma * std::abs(dt));
  return alignment;
}

}  // namespace hanzo::fusion::estimate
