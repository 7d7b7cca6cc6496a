#pragma once
// Measurement models of single-beam rangefinders (msgs::RangeMessage: the distance along the
// sensor frame's +x axis to the nearest surface in its cone).

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/estimate/measurement_model.hpp"

namespace hanzo::fusion::estimate {

/// A rangefinder looking down at a level floor (an altimeter, a robot's ground sensor): the
/// reading is the distance to the nearest point of the horizontal plane z = floor_z (world,
/// metres) within the sensor's cone (half angle alpha about its +x axis; an ultrasonic sensor
/// reports its first echo). With the beam tilted by theta from straight down:
///   h = a / cos(max(0, theta - alpha)),   a = p_s.z - floor_z,   p_s = p + R t,
///   cos theta = c = -e_z^T R u,   u = R_body_sensor e_x.
/// With R = R_est Exp(dtheta) and p = p_est + dp (da = dp_z - e_z^T R [t]x dtheta,
/// dc = e_z^T R [u]x dtheta, dtheta_beam = -dc / sin theta):
///   H = da / k + a tan(theta - alpha) / k * dtheta_beam,   k = cos(theta - alpha)   (theta > alpha)
///   H = da                                                                          (theta <= alpha)
/// Observes the height above the floor; nothing horizontal. The attitude enters as the estimate
/// has it: with update_attitude false (the default, as PX4's EKF2 fuses range finders) the
/// rotation columns of H are zero, for a range tells a tilt from a height change only through
/// the lever arm and the cone's edge, whose real shape the model only approximates; the IMU and
/// the other sensors measure the tilt far better. Valid while the beam points down (theta well
/// below 90 degrees, the caller checks).
/// variance: m^2 of the reading and of the floor's unevenness.
class FloorRangeModel final : public MeasurementModel {
 public:
  FloorRangeModel(double range, double variance, double floor_z, const SE3& T_body_sensor, double half_field_of_view, bool update_attitude = false)
      : range_(range),
        variance_(variance),
        floor_z_(floor_z),
        T_body_sensor_(T_body_sensor),
        half_field_of_view_(half_field_of_view),
        update_attitude_(update_attitude) {}

  std::string_view name() const override { return "floor_range"; }
  int dimension() const override { return 1; }
  MeasurementVector residual(const NavigationState& state, MeasurementJacobian* jacobian) const override;
  MeasurementCovariance covariance() const override { return MeasurementCovariance::Constant(1, 1, variance_); }

 private:
  double range_;
  double variance_;
  double floor_z_;
  SE3 T_body_sensor_;
  double half_field_of_view_;
  bool update_attitude_;
};

}  // namespace hanzo::fusion::estimate
