#include "hanzo/fusion/core/so3.hpp"

#include <cassert>
#include <cmath>

namespace hanzo::fusion {
namespace {

// Below this angle the closed forms lose precision and the Taylor series are used.
constexpr double kSmallAngle = 1e-5;

// Coefficients of Jl(phi) = I + a * hat + b * hat^2, with theta = |phi|.
void left_jacobian_coefficients(double theta, double* a, double* b) {
  if (theta < kSmallAngle) {
    const double theta2 = theta * theta;
    *a = 0.5 - theta2 / 24.0;
    *b = 1.0 / 6.0 - theta2 / 120.0;
    return;
  }
  const double theta2 = theta * theta;
  *a = (1.0 - std::cos(theta)) / theta2;
  *b = (theta - std::sin(theta)) / (theta2 * theta);
}

// Coefficient c of Jl^-1(phi) = I - 0.5 hat + c * hat^2.
double left_jacobian_inverse_coefficient(double theta) {
  if (theta < kSmallAngle) return 1.0 / 12.0 + theta * theta / 720.0;
  const double half = 0.5 * theta;
  return (1.0 - half * std::cos(half) / std::sin(half)) / (theta * theta);
}

}  // namespace

SO3::SO3(const Eigen::Quaterniond& unit_quaternion) : q_(unit_quaternion) {
  assert(std::abs(q_.squaredNorm() - 1.0) < 1e-6);
  if (q_.w() < 0) q_.coeffs() = -q_.coeffs();
}

SO3 SO3::from_quaternion_normalized(const Eigen::Quaterniond& q) {
  assert(q.norm() > 0);
  return SO3(q.normalized());
}

SO3 SO3::from_wxyz(const Eigen::Vector4d& wxyz) {
  return SO3(Eigen::Quaterniond(wxyz[0], wxyz[1], wxyz[2], wxyz[3]));
}

SO3 SO3::from_matrix(const Eigen::Matrix3d& rotation_matrix) {
  return from_quaternion_normalized(Eigen::Quaterniond(rotation_matrix));
}

SO3 SO3::from_axis_angle(const Eigen::Vector3d& unit_axis, double angle) {
  return exp(unit_axis * angle);
}

Eigen::Vector4d SO3::wxyz() const { return {q_.w(), q_.x(), q_.y(), q_.z()}; }

SO3 SO3::exp(const Tangent& phi, Jacobian* jacobian) {
  const double theta2 = phi.squaredNorm();
  const double theta = std::sqrt(theta2);
  double real;
  double imaginary_factor;  // sin(theta/2) / theta
  if (theta < kSmallAngle) {
    real = 1.0 - theta2 / 8.0;
    imaginary_factor = 0.5 - theta2 / 48.0;
  } else {
    real = std::cos(0.5 * theta);
    imaginary_factor = std::sin(0.5 * theta) / theta;
  }
  if (jacobian) *jacobian = right_jacobian(phi);
  // Unit norm to rounding in both branches (the series' error is O(theta^4) < 1e-20).
  return SO3(Eigen::Quaterniond(real, imaginary_factor * phi.x(), imaginary_factor * phi.y(), imaginary_factor * phi.z()));
}

SO3::Tangent SO3::log(Jacobian* jacobian) const {
  // q = (cos(theta/2), sin(theta/2) * axis) with w >= 0, so theta in [0, pi]. atan2 keeps full
  // precision both near identity (small vector part) and near pi (small w).
  const Eigen::Vector3d v = q_.vec();
  const double v_norm = v.norm();
  const double w = q_.w();
  Tangent phi;
  if (v_norm < kSmallAngle) {
    // theta ~ 2 v_norm / w; series of 2 atan(x)/x with x = v_norm / w.
    const double x2 = v_norm * v_norm / (w * w);
    phi = (2.0 / w) * (1.0 - x2 / 3.0) * v;
  } else {
    const double theta = 2.0 * std::atan2(v_norm, w);
    phi = (theta / v_norm) * v;
  }
  if (jacobian) *jacobian = right_jacobian_inverse(phi);
  return phi;
}

SO3 SO3::inverse(Jacobian* jacobian) const {
  if (jacobian) *jacobian = -matrix();
  return SO3(q_.conjugate());
}

SO3 SO3::compose(const SO3& other, Jacobian* jacobian_this, Jacobian* jacobian_other) const {
  if (jacobian_this) *jacobian_this = other.matrix().transpose();
  if (jacobian_other) jacobian_other->setIdentity();
  return SO3((q_ * other.q_).normalized());
}

Eigen::Vector3d SO3::act(const Eigen::Vector3d& point, Eigen::Matrix3d* jacobian_rotation,
                         Eigen::Matrix3d* jacobian_point) const {
  if (jacobian_rotation || jacobian_point) {
    const Eigen::Matrix3d rotation = matrix();
    if (jacobian_rotation) *jacobian_rotation = -rotation * hat(point);
    if (jacobian_point) *jacobian_point = rotation;
  }
  return q_ * point;
}

SO3 SO3::interpolate(const SO3& a, const SO3& b, double t) {
  return a * exp(t * (a.inverse() * b).log());
}

double SO3::angle() const { return 2.0 * std::atan2(q_.vec().norm(), q_.w()); }

Eigen::Matrix3d SO3::hat(const Tangent& phi) {
  Eigen::Matrix3d skew;
  skew << 0.0, -phi.z(), phi.y(),
          phi.z(), 0.0, -phi.x(),
          -phi.y(), phi.x(), 0.0;
  return skew;
}

SO3::Tangent SO3::vee(const Eigen::Matrix3d& skew) { return {skew(2, 1), skew(0, 2), skew(1, 0)}; }

SO3::Jacobian SO3::left_jacobian(const Tangent& phi) {
  double a;
  double b;
  left_jacobian_coefficients(phi.norm(), &a, &b);
  const Eigen::Matrix3d skew = hat(phi);
  return Eigen::Matrix3d::Identity() + a * skew + b * skew * skew;
}

SO3::Jacobian SO3::right_jacobian(const Tangent& phi) { return left_jacobian(-phi); }

SO3::Jacobian SO3::left_jacobian_inverse(const Tangent& phi) {
  const Eigen::Matrix3d skew = hat(phi);
  return Eigen::Matrix3d::Identity() - 0.5 * skew + left_jacobian_inverse_coefficient(phi.norm()) * skew * skew;
}

SO3::Jacobian SO3::right_jacobian_inverse(const Tangent& phi) { return left_jacobian_inverse(-phi); }

}  // namespace hanzo::fusion
