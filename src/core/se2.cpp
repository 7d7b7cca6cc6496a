#include "hanzo/fusion/core/se2.hpp"

#include <cmath>
#include <numbers>

#include <Eigen/LU>

namespace hanzo::fusion {
namespace {

constexpr double kSmallAngle = 1e-5;

// V(theta) with t = V rho for exp((rho, theta)); Sola eq. (158).
Eigen::Matrix2d v_matrix(double theta) {
  double a;  // sin(theta) / theta
  double b;  // (1 - cos(theta)) / theta
  if (std::abs(theta) < kSmallAngle) {
    a = 1.0 - theta * theta / 6.0;
    b = 0.5 * theta;
  } else {
    a = std::sin(theta) / theta;
    b = (1.0 - std::cos(theta)) / theta;
  }
  Eigen::Matrix2d v;
  v << a, -b, b, a;
  return v;
}

}  // namespace

SE2::SE2(double theta, const Eigen::Vector2d& translation) : theta_(wrap_angle(theta)), translation_(translation) {}

double SE2::wrap_angle(double angle) {
  double wrapped = std::remainder(angle, 2.0 * std::numbers::pi);  // in [-pi, pi]
  if (wrapped <= -std::numbers::pi) wrapped += 2.0 * std::numbers::pi;
  return wrapped;
}

SE2 SE2::exp(const Tangent& tangent) {
  return {tangent.z(), v_matrix(tangent.z()) * tangent.head<2>()};
}

SE2::Tangent SE2::log() const {
  Tangent tangent;
  tangent << v_matrix(theta_).inverse() * translation_, theta_;
  return tangent;
}

Eigen::Matrix2d SE2::rotation_matrix() const {
  const double c = std::cos(theta_);
  const double s = std::sin(theta_);
  Eigen::Matrix2d r;
  r << c, -s, s, c;
  return r;
}

Eigen::Matrix3d SE2::matrix() const {
  Eigen::Matrix3d m = Eigen::Matrix3d::Identity();
  m.topLeftCorner<2, 2>() = rotation_matrix();
  m.topRightCorner<2, 1>() = translation_;
  return m;
}

SE2 SE2::inverse(Jacobian* jacobian) const {
  if (jacobian) *jacobian = -adjoint();
  return {-theta_, -(rotation_matrix().transpose() * translation_)};
}

SE2 SE2::compose(const SE2& other, Jacobian* jacobian_this, Jacobian* jacobian_other) const {
  if (jacobian_this) *jacobian_this = other.inverse().adjoint();
  if (jacobian_other) jacobian_other->setIdentity();
  return {theta_ + other.theta_, rotation_matrix() * other.translation_ + translation_};
}

SE2::Jacobian SE2::adjoint() const {
  Jacobian ad = Jacobian::Identity();
  ad.topLeftCorner<2, 2>() = rotation_matrix();
  ad(0, 2) = translation_.y();
  ad(1, 2) = -translation_.x();
  return ad;
}

SE2 SE2::interpolate(const SE2& a, const SE2& b, double t) {
  return a * exp(t * (a.inverse() * b).log());
}

}  // namespace hanzo::fusion
