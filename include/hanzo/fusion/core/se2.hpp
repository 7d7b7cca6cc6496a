#pragma once
// SE2: planar rigid transforms T_a_b = (theta, t) for ground robots and 2D laser SLAM,
// p_a = R(theta) p_b + t. Tangent vectors are (x, y, theta), translational part first as in
// SE3. Jacobians use the right perturbation X * exp(d).
// Reference: Sola et al., "A micro Lie theory for state estimation in robotics" (2018),
// Appendix C, eqs. (156)-(164).

#include <Eigen/Core>

namespace hanzo::fusion {

class SE2 {
 public:
  using Tangent = Eigen::Vector3d;
  using Jacobian = Eigen::Matrix3d;

  SE2() = default;
  /// theta in radians (any value; stored wrapped to (-pi, pi]).
  SE2(double theta, const Eigen::Vector2d& translation);
  static SE2 identity() { return {}; }

  /// jacobian receives Jr(tangent).
  static SE2 exp(const Tangent& tangent, Jacobian* jacobian = nullptr);
  /// Returns (x, y, theta) with theta in (-pi, pi]. jacobian receives Jr^-1(log(T)).
  Tangent log(Jacobian* jacobian = nullptr) const;

  double angle() const { return theta_; }
  const Eigen::Vector2d& translation() const { return translation_; }
  Eigen::Matrix2d rotation_matrix() const;
  Eigen::Matrix3d matrix() const;

  /// Inverse. Jacobian: -Ad(T).
  SE2 inverse(Jacobian* jacobian = nullptr) const;
  /// this * other. Jacobians: d/d this = Ad(other^-1), d/d other = I.
  SE2 compose(const SE2& other, Jacobian* jacobian_this = nullptr, Jacobian* jacobian_other = nullptr) const;
  SE2 operator*(const SE2& other) const { return compose(other); }
  Eigen::Vector2d act(const Eigen::Vector2d& point) const { return rotation_matrix() * point + translation_; }
  Eigen::Vector2d operator*(const Eigen::Vector2d& point) const { return act(point); }

  /// Adjoint [[R, (t_y, -t_x)], [0, 1]].
  Jacobian adjoint() const;
  /// a * exp(t log(a^-1 b)).
  static SE2 interpolate(const SE2& a, const SE2& b, double t);

  /// Right Jacobian, Sola eq. (163): exp(t + d) ~ exp(t) exp(Jr(t) d).
  static Jacobian right_jacobian(const Tangent& tangent);
  /// Left Jacobian Jl(t) = Jr(-t): exp(t + d) ~ exp(Jl(t) d) exp(t).
  static Jacobian left_jacobian(const Tangent& tangent) { return right_jacobian(-tangent); }
  static Jacobian right_jacobian_inverse(const Tangent& tangent);
  static Jacobian left_jacobian_inverse(const Tangent& tangent) { return right_jacobian_inverse(-tangent); }

  /// Wraps an angle to (-pi, pi].
  static double wrap_angle(double angle);

 private:
  double theta_ = 0.0;
  Eigen::Vector2d translation_ = Eigen::Vector2d::Zero();
};

}  // namespace hanzo::fusion
