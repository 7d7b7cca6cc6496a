#pragma once
// SO3: 3D rotations as unit quaternions, with the Lie-group operations estimators need.
//
// Conventions (used throughout hanzo-fusion):
//  - A rotation R_a_b maps coordinates in frame b into frame a: p_a = R_a_b * p_b.
//  - Tangent vectors are rotation vectors phi (axis * angle, radians) in R^3.
//  - exp/log are the exponential and logarithm maps; hat(phi) is the skew matrix [phi]x.
//  - Jacobians of operations use the RIGHT perturbation X (+) delta = X * exp(delta), as GTSAM
//    and Forster et al. 2017 do. The Jacobian of f(X) is J with f(X exp(d)) ~ f(X) exp(J d).
//  - Quaternions are stored and exchanged as (w, x, y, z) with w >= 0 after normalization
//    (q and -q are the same rotation; log() always returns an angle in [0, pi]).
//
// References: J. Sola, J. Deray, D. Atchuthan, "A micro Lie theory for state estimation in
// robotics" (2018), eqs. (143)-(146) for the SO3 Jacobians; T. Barfoot, "State Estimation for
// Robotics" (2017), eqs. (7.77)-(7.78) for the left Jacobian and its inverse.

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace hanzo::fusion {

class SO3 {
 public:
  using Tangent = Eigen::Vector3d;
  using Jacobian = Eigen::Matrix3d;

  /// Identity rotation.
  SO3() = default;
  /// From a quaternion that must already be unit norm (asserted to 1e-6 in debug builds);
  /// use from_quaternion_normalized() for inputs that need normalizing.
  explicit SO3(const Eigen::Quaterniond& unit_quaternion);

  static SO3 identity() { return {}; }
  /// Normalizes q (which must be non-zero) and returns the rotation.
  static SO3 from_quaternion_normalized(const Eigen::Quaterniond& q);
  /// From (w, x, y, z), which must be unit norm.
  static SO3 from_wxyz(const Eigen::Vector4d& wxyz);
  /// From a rotation matrix; the closest rotation is taken (the input should be orthonormal).
  static SO3 from_matrix(const Eigen::Matrix3d& rotation_matrix);
  /// Rotation about a unit axis by angle radians.
  static SO3 from_axis_angle(const Eigen::Vector3d& unit_axis, double angle);

  /// exp: rotation vector -> rotation. Exact for all angles; Taylor series near zero.
  /// If jacobian is given it receives the right Jacobian Jr(phi) (d exp(phi) / d phi).
  static SO3 exp(const Tangent& phi, Jacobian* jacobian = nullptr);
  /// log: rotation -> rotation vector with angle in [0, pi]. Stable near identity and near pi.
  /// If jacobian is given it receives Jr^-1(log(R)) (d log(R) / dR, right perturbation).
  Tangent log(Jacobian* jacobian = nullptr) const;

  const Eigen::Quaterniond& quaternion() const { return q_; }
  /// (w, x, y, z), w >= 0.
  Eigen::Vector4d wxyz() const;
  Eigen::Matrix3d matrix() const { return q_.toRotationMatrix(); }

  /// Inverse (transpose). Jacobian d inv / d R = -Ad(R) = -R.
  SO3 inverse(Jacobian* jacobian = nullptr) const;
  /// Composition this * other. Jacobians: d/d this = R_other^T, d/d other = I.
  SO3 compose(const SO3& other, Jacobian* jacobian_this = nullptr, Jacobian* jacobian_other = nullptr) const;
  SO3 operator*(const SO3& other) const { return compose(other); }
  /// Rotates a point: R * p. Jacobians: d/dR = -R hat(p), d/dp = R.
  Eigen::Vector3d act(const Eigen::Vector3d& point, Eigen::Matrix3d* jacobian_rotation = nullptr,
                      Eigen::Matrix3d* jacobian_point = nullptr) const;
  Eigen::Vector3d operator*(const Eigen::Vector3d& point) const { return q_ * point; }

  /// Adjoint: Ad(R) = R, so that R exp(phi) = exp(Ad(R) phi) R.
  Eigen::Matrix3d adjoint() const { return matrix(); }

  /// Geodesic interpolation (slerp): t = 0 gives a, t = 1 gives b; a * exp(t * log(a^-1 b)).
  static SO3 interpolate(const SO3& a, const SO3& b, double t);

  /// Angle of this rotation in radians, in [0, pi].
  double angle() const;

  static Eigen::Matrix3d hat(const Tangent& phi);
  static Tangent vee(const Eigen::Matrix3d& skew);
  /// Right Jacobian Jr(phi) = Jl(-phi); exp(phi + d) ~ exp(phi) exp(Jr(phi) d).
  static Jacobian right_jacobian(const Tangent& phi);
  static Jacobian right_jacobian_inverse(const Tangent& phi);
  /// Left Jacobian Jl(phi); exp(phi + d) ~ exp(Jl(phi) d) exp(phi). Barfoot eq. (7.77a).
  static Jacobian left_jacobian(const Tangent& phi);
  /// Barfoot eq. (7.77b). Singular at |phi| = 2 pi (never reached for log() outputs).
  static Jacobian left_jacobian_inverse(const Tangent& phi);

 private:
  Eigen::Quaterniond q_ = Eigen::Quaterniond::Identity();
};

}  // namespace hanzo::fusion
