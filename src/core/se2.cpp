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

SE2 SE2::exp(const Tangent& tangent, Jacobian* jacobian) {
  if (jacobian) *jacobian = right_jacobian(tangent);
  return {tangent.z(), v_matrix(tangent.z()) * tangent.head<2>()};
}

SE2::Tangent SE2::log(Jacobian* jacobian) const {
  Tangent tangent;
  tangent << v_matrix(theta_).inverse() * translation_, theta_;
  if (jacobian) *jacobian = right_jacobian_inverse(tangent);
  return tangent;
}

SE2::Jacobian SE2::right_jacobian(const Tangent& tangent) {
  const double x = tangent.x();
  const double y = tangent.y();
  const double theta = tangent.z();
  double a;  // sin(theta) / theta
  double b;  // (1 - cos(theta)) / theta
  double c;  // (theta - sin(theta)) / theta^2
  double d;  // (1 - cos(theta)) / theta^2
  if (std::abs(theta) < kSmallAngle) {
    const double theta2 = theta * theta;
    a = 1.0 - theta2 / 6.0;
    b = 0.5 * theta;
    c = theta / 6.0;
    d = 0.5 - theta2 / 24.0;
  } else {
    const double s = std::sin(theta);
    const double cosine = std::cos(theta);
    a = s / theta;
    b = (1.0 - cosine) / theta;
    c = (theta - s) / (theta * theta);
    d = (1.0 - cosine) / (theta * theta);
  }
  Jacobian jacobian;
  jacobian << a, b, c * x - d * y,
              -b, a, d * x + c * y,
              0.0, 0.0, 1.0;
  return jacobian;
}

SE2::Jacobian SE2::right_jacobian_inverse(const Tangent& tangent) {
  // [[A, v], [0, 1]]^-1 = [[A^-1, -A^-1 v], [0, 1]].
  const Jacobian jacobian = right_jacobian(tangent);
  const Eigen::Matrix2d a_inverse = jacobian.topLeftCorner<2, 2>().inverse();
  Jacobian inverse = Jacobian::Identity();
  inverse.topLeftCorner<2, 2>() = a_inverse;
  inverse.topRightCorner<2, 1>() = -a_inverse * jacobian.topRightCorner<2, 1>();
  return inverse;
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
