#include "hanzo/fusion/estimate/range_models.hpp"

#include <algorithm>
#include <cmath>

namespace hanzo::fusion::estimate {

MeasurementVector FloorRangeModel::residual(const NavigationState& state, MeasurementJacobian* jacobian) const {
  const Eigen::Matrix3d R = state.R_world_body.matrix();
  const Eigen::Vector3d& t = T_body_sensor_.translation();
  const Eigen::Vector3d u = T_body_sensor_.rotation() * Eigen::Vector3d::UnitX();
  const double height = (state.position + R * t).z() - floor_z_;
  const double c = std::clamp(-(R * u).z(), -1.0, 1.0);
  const double tilt = std::acos(c);
  const double slant = std::max(0.0, tilt - half_field_of_view_);  // the cone's ray nearest to straight down
  const double k = std::cos(slant);
  const double predicted = height / k;
  if (jacobian != nullptr) {
    jacobian->setZero(1, kErrorStateDimension);
    (*jacobian)(0, 2) = 1.0 / k;
    if (update_attitude_) {
      const Eigen::RowVector3d z_row = R.row(2);
      Eigen::RowVector3d by_rotation = -(z_row * SO3::hat(t)) / k;
      if (slant > 0.0) {
        const Eigen::RowVector3d tilt_by_rotation = -(z_row * SO3::hat(u)) / std::sin(tilt);
        by_rotation += height * std::tan(slant) / k * tilt_by_rotation;
      }
      jacobian->block<1, 3>(0, 3) = by_rotation;
    }
  }
  MeasurementVector r(1);
  r(0) = range_ - predicted;
  return r;
}

}  // namespace hanzo::fusion::estimate
