#pragma once
// Measurement models of absolute position and pose (measurement_model.hpp for the contract).

#include <Eigen/Core>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/estimate/measurement_model.hpp"

namespace hanzo::fusion::estimate {

/// GNSS antenna position in the world frame (ENU around the datum; converting WGS84 to ENU is
/// the caller's job, pipeline::Frontend does it with core/geodesy.hpp).
///   h(x) = p + R p_body_antenna            (lever arm from the calibration's gnss_to_body)
///   H    = [I, -R [p_body_antenna]x, 0, ...]
class GnssPositionModel final : public MeasurementModel {
 public:
  /// covariance: m^2, ENU (the message's position_covariance, or one the fix-type policy set).
  GnssPositionModel(const Eigen::Vector3d& antenna_position_world, const Eigen::Matrix3d& covariance,
                    const Eigen::Vector3d& p_body_antenna)
      : measured_(antenna_position_world), covariance_(covariance), p_body_antenna_(p_body_antenna) {}

  std::string_view name() const override { return "gnss_position"; }
  int dimension() const override { return 3; }
  MeasurementVector residual(const NavigationState& state, MeasurementJacobian* jacobian) const override;
  MeasurementCovariance covariance() const override { return covariance_; }

 private:
  Eigen::Vector3d measured_;
  Eigen::Matrix3d covariance_;
  Eigen::Vector3d p_body_antenna_;
};

/// A 6-DOF pose of a sensor in the world frame (LiDAR or visual localization against a map,
/// motion capture): z = T_world_sensor.
///   residual = (z_p - (p + R t_body_sensor),  log((R R_body_sensor)^T z_R))
///   H        = [[I, -R [t]x, 0...], [0, Jl^-1(r_rot) R_body_sensor^T, 0...]]
/// covariance: 6x6 over (position error in the world [m], rotation error in the sensor frame
/// [rad], z_true = z Exp(e)), the layout of PoseEstimate.pose_covariance.
class PoseModel final : public MeasurementModel {
 public:
  PoseModel(const SE3& T_world_sensor, const Eigen::Matrix<double, 6, 6>& covariance, const SE3& T_body_sensor)
      : measured_(T_world_sensor), covariance_(covariance), T_body_sensor_(T_body_sensor) {}

  std::string_view name() const override { return "pose"; }
  int dimension() const override { return 6; }
  MeasurementVector residual(const NavigationState& state, MeasurementJacobian* jacobian) const override;
  MeasurementCovariance covariance() const override { return covariance_; }

 private:
  SE3 measured_;
  Eigen::Matrix<double, 6, 6> covariance_;
  SE3 T_body_sensor_;
};

}  // namespace hanzo::fusion::estimate
