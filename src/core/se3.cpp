#include "hanzo/fusion/core/se3.hpp"

#include <cmath>

namespace hanzo::fusion {
namespace {

constexpr double kSmallAngle = 1e-4;

// Q(rho, phi) of Barfoot eq. (7.86b), the off-diagonal block of the SE3 left Jacobian.
Eigen::Matrix3d q_block(const Eigen::Vector3d& rho, const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const double theta2 = theta * theta;
  double c1;  // (theta - sin) / theta^3
  double c2;  // (theta^2 + 2 cos - 2) / (2 theta^4)
  double c3;  // (2 theta - 3 sin + theta cos) / (2 theta^5)
  if (theta < kSmallAngle) {
    c1 = 1.0 / 6.0 - theta2 / 120.0;
    c2 = 1.0 / 24.0 - theta2 / 720.0;
    c3 = 1.0 / 120.0 - theta2 / 2520.0;
  } else {
    const double s = std::sin(theta);
    const double c = std::cos(theta);
    c1 = (theta - s) / (theta2 * theta);
    c2 = (theta2 + 2.0 * c - 2.0) / (2.0 * theta2 * theta2);
    c3 = (2.0 * theta - 3.0 * s + theta * c) / (2.0 * theta2 * theta2 * theta);
  }
  const Eigen::Matrix3d p = SO3::hat(phi);
  const Eigen::Matrix3d r = SO3::hat(rho);
  const Eigen::Matrix3d pr = p * r;
  const Eigen::Matrix3d rp = r * p;
  const Eigen::Matrix3d prp = pr * p;
  return 0.5 * r + c1 * (pr + rp + prp) + c2 * (p * pr + rp * p - 3.0 * prp) + c3 * (prp * p + p * prp);
}

}  // namespace

SE3 SE3::from_matrix(const Eigen::Matrix4d& matrix) {
  return {SO3::from_matrix(matrix.topLeftCorner<3, 3>()), matrix.topRightCorner<3, 1>()};
}

SE3 SE3::exp(const Tangent& xi, Jacobian* jacobian) {
  const Eigen::Vector3d rho = xi.head<3>();
  const Eigen::Vector3d phi = xi.tail<3>();
  if (jacobian) *jacobian = right_jacobian(xi);
  return {SO3::exp(phi), SO3::left_jacobian(phi) * rho};
}

SE3::Tangent SE3::log(Jacobian* jacobian) const {
  const Eigen::Vector3d phi = rotation_.log();
  Tangent xi;
  xi << SO3::left_jacobian_inverse(phi) * translation_, phi;
  if (jacobian) *jacobian = right_jacobian_inverse(xi);
  return xi;
}

Eigen::Matrix4d SE3::matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = rotation_.matrix();
  m.topRightCorner<3, 1>() = translation_;
  return m;
}

SE3 SE3::inverse(Jacobian* jacobian) const {
  if (jacobian) *jacobian = -adjoint();
  const SO3 rotation_inverse = rotation_.inverse();
  return {rotation_inverse, -(rotation_inverse * translation_)};
}

SE3 SE3::compose(const SE3& other, Jacobian* jacobian_this, Jacobian* jacobian_other) const {
  if (jacobian_this) *jacobian_this = other.inverse().adjoint();
  if (jacobian_other) jacobian_other->setIdentity();
  return {rotation_ * other.rotation_, rotation_ * other.translation_ + translation_};
}

Eigen::Vector3d SE3::act(const Eigen::Vector3d& point, Eigen::Matrix<double, 3, 6>* jacobian_pose,
                         Eigen::Matrix3d* jacobian_point) const {
  if (jacobian_pose || jacobian_point) {
    const Eigen::Matrix3d rotation = rotation_.matrix();
    if (jacobian_pose) *jacobian_pose << rotation, -rotation * SO3::hat(point);
    if (jacobian_point) *jacobian_point = rotation;
  }
  return rotation_ * point + translation_;
}

SE3::Jacobian SE3::adjoint() const {
  const Eigen::Matrix3d rotation = rotation_.matrix();
  Jacobian ad;
  ad << rotation, SO3::hat(translation_) * rotation, Eigen::Matrix3d::Zero(), rotation;
  return ad;
}

SE3 SE3::interpolate(const SE3& a, const SE3& b, double t) {
  return a * exp(t * (a.inverse() * b).log());
}

SE3::Jacobian SE3::left_jacobian(const Tangent& xi) {
  const Eigen::Vector3d rho = xi.head<3>();
  const Eigen::Vector3d phi = xi.tail<3>();
  const Eigen::Matrix3d jl = SO3::left_jacobian(phi);
  Jacobian j;
  j << jl, q_block(rho, phi), Eigen::Matrix3d::Zero(), jl;
  return j;
}

SE3::Jacobian SE3::left_jacobian_inverse(const Tangent& xi) {
  const Eigen::Vector3d rho = xi.head<3>();
  const Eigen::Vector3d phi = xi.tail<3>();
  const Eigen::Matrix3d jl_inverse = SO3::left_jacobian_inverse(phi);
  Jacobian j;
  j << jl_inverse, -jl_inverse * q_block(rho, phi) * jl_inverse, Eigen::Matrix3d::Zero(), jl_inverse;
  return j;
}

}  // namespace hanzo::fusion
