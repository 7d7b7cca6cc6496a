#include "hanzo/fusion/sim/spline_trajectory.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace hanzo::fusion::sim {

Result<SplineTrajectory> SplineTrajectory::create(Timestamp start_time, Duration knot_spacing, std::vector<SE3> control_poses) {
  if (control_poses.size() < 4) {
    return Error(fmt::format("spline trajectory: {} control poses (a cubic B-spline needs at least 4)", control_poses.size()));
  }
  if (knot_spacing.nanoseconds() <= 0) return Error("spline trajectory: knot spacing must be positive");
  return SplineTrajectory(start_time, knot_spacing.seconds(), std::move(control_poses));
}

Timestamp SplineTrajectory::end_time() const {
  return start_ + Duration::from_seconds(spacing_ * static_cast<double>(control_.size() - 3));
}

TrajectorySample SplineTrajectory::sample(Timestamp time) const {
  const double t = std::clamp((time - start_).seconds(), 0.0, spacing_ * static_cast<double>(control_.size() - 3));
  const auto segment = std::min(static_cast<std::size_t>(t / spacing_), control_.size() - 4);
  const double u = t / spacing_ - static_cast<double>(segment);
  // Cumulative basis B~_j(u), j = 1..3, and its first two derivatives in u (Lovegrove eq. 4-6).
  const double u2 = u * u, u3 = u2 * u;
  const double b[4] = {1.0, (5.0 + 3.0 * u - 3.0 * u2 + u3) / 6.0, (1.0 + 3.0 * u + 3.0 * u2 - 2.0 * u3) / 6.0, u3 / 6.0};
  const double db[4] = {0.0, (3.0 - 6.0 * u + 3.0 * u2) / 6.0, (3.0 + 6.0 * u - 6.0 * u2) / 6.0, u2 / 2.0};
  const double ddb[4] = {0.0, u - 1.0, 1.0 - 2.0 * u, u};

  TrajectorySample out;
  Eigen::Vector3d position = control_[segment].translation();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero(), acceleration = Eigen::Vector3d::Zero();
  SO3 rotation = control_[segment].rotation();
  Eigen::Vector3d omega = Eigen::Vector3d::Zero();  // body angular velocity per unit u
  for (int j = 1; j <= 3; ++j) {
    const SE3& previous = control_[segment + j - 1];
    const SE3& next = control_[segment + j];
    const Eigen::Vector3d dp = next.translation() - previous.translation();
    position += b[j] * dp;
    velocity += db[j] * dp;
    acceleration += ddb[j] * dp;
    // R = R_i prod exp(B~_j d_j); body rate recursion omega_j = A_j^T omega_{j-1} + dB~_j d_j (Sommer eq. 38).
    const Eigen::Vector3d d = (previous.rotation().inverse() * next.rotation()).log();
    const SO3 step = SO3::exp(b[j] * d);
    rotation = rotation * step;
    omega = step.inverse() * omega + db[j] * d;
  }
  out.T_world_body = SE3(rotation, position);
  out.velocity_world = velocity / spacing_;
  out.acceleration_world = acceleration / (spacing_ * spacing_);
  out.angular_velocity_body = omega / spacing_;
  return out;
}

}  // namespace hanzo::fusion::sim
