#pragma once
// SE3: rigid transforms T_a_b = (R_a_b, t_a_b) mapping frame-b coordinates into frame a:
// p_a = R_a_b * p_b + t_a_b. Composition chains frames: T_a_c = T_a_b * T_b_c.
//
// Tangent vectors are xi = (rho, phi) in R^6: the translational part first, then the rotation
// vector (Sophus / Barfoot ordering; the same order as ROS pose covariances x y z rx ry rz).
// Jacobians use the right perturbation X (+) d = X * exp(d), see so3.hpp.
//
// References: T. Barfoot, "State Estimation for Robotics" (2017): exp/log eqs. (7.83)-(7.85),
// the left Jacobian eq. (7.85) with Q(rho, phi) eq. (7.86b), its inverse eq. (7.95).

#include <Eigen/Core>

#include "hanzo/fusion/core/so3.hpp"

namespace hanzo::fusion {

class SE3 {
 public:
  using Tangent = Eigen::Matrix<double, 6, 1>;
  using Jacobian = Eigen::Matrix<double, 6, 6>;

  SE3() = default;
  SE3(const SO3& rotation, const Eigen::Vector3d& translation) : rotation_(rotation), translation_(translation) {}
  static SE3 identity() { return {}; }
  /// From a 4x4 homogeneous matrix; the rotation block should be orthonormal.
  static SE3 from_matrix(const Eigen::Matrix4d& matrix);

  /// exp((rho, phi)) = (exp(phi), Jl(phi) rho). jacobian receives Jr(xi).
  static SE3 exp(const Tangent& xi, Jacobian* jacobian = nullptr);
  /// Inverse of exp, rotation angle in [0, pi]. jacobian receives Jr^-1(log(T)).
  Tangent log(Jacobian* jacobian = nullptr) const;

  const SO3& rotation() const { return rotation_; }
  const Eigen::Vector3d& translation() const { return translation_; }
  SO3& rotation() { return rotation_; }
  Eigen::Vector3d& translation() { return translation_; }
  Eigen::Matrix4d matrix() const;

  /// Inverse T^-1 = (R^T, -R^T t). Jacobian: -Ad(T).
  SE3 inverse(Jacobian* jacobian = nullptr) const;
  /// this * other. Jacobians: d/d this = Ad(other^-1), d/d other = I.
  SE3 compose(const SE3& other, Jacobian* jacobian_this = nullptr, Jacobian* jacobian_other = nullptr) const;
  SE3 operator*(const SE3& other) const { return compose(other); }
  /// Transforms a point: R p + t. Jacobians: d/dT = [R, -R hat(p)] (3x6), d/dp = R.
  Eigen::Vector3d act(const Eigen::Vector3d& point, Eigen::Matrix<double, 3, 6>* jacobian_pose = nullptr,
                      Eigen::Matrix3d* jacobian_point = nullptr) const;
  Eigen::Vector3d operator*(const Eigen::Vector3d& point) const { return rotation_ * point + translation_; }

  /// Adjoint [[R, hat(t) R], [0, R]], so that T exp(xi) = exp(Ad(T) xi) T.
  Jacobian adjoint() const;

  /// Geodesic interpolation on SE3 (constant-twist screw motion): a * exp(t log(a^-1 b)).
  static SE3 interpolate(const SE3& a, const SE3& b, double t);

  /// Left Jacobian Jl(xi) = [[Jl(phi), Q], [0, Jl(phi)]], Barfoot eq. (7.85).
  static Jacobian left_jacobian(const Tangent& xi);
  static Jacobian left_jacobian_inverse(const Tangent& xi);
  /// Jr(xi) = Jl(-xi).
  static Jacobian right_jacobian(const Tangent& xi) { return left_jacobian(-xi); }
  static Jacobian right_jacobian_inverse(const Tangent& xi) { return left_jacobian_inverse(-xi); }

 private:
  SO3 rotation_;
  Eigen::Vector3d translation_ = Eigen::Vector3d::Zero();
};

}  // namespace hanzo::fusion
