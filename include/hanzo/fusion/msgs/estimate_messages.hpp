#pragma once
// What the engine produces: PoseEstimate at sensor rate and Keyframes for the backend
// (proto/hanzo/fusion/v1/estimates.proto).

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/core/time.hpp"

namespace hanzo::fusion::msgs {

using Matrix6d = Eigen::Matrix<double, 6, 6>;

enum class TrackingState { kUnspecified, kInitializing, kTracking, kDegraded, kLost };
std::string_view to_string(TrackingState state);

/// A sensor's health (spec: degraded mode per modality; pipeline/sensor_health.hpp says when).
enum class HealthState { kOk, kDegraded, kLost };
enum class HealthReason {
  kNone, kTimeout, kGated, kNoFix, kDegenerateGeometry, kWeather, kSlip, kNotRegistered, kNotFused,
  kDark, kGlare, kMotionBlur, kFewFeatures  // a camera's tracking lost, and why
};
std::string_view to_string(HealthState state);    // "ok", "degraded", "lost"
std::string_view to_string(HealthReason reason);  // "", "timeout", "gated", "no_fix", "degenerate_geometry", ...

struct SensorHealthStatus {
  std::string sensor;
  HealthState state = HealthState::kOk;
  HealthReason reason = HealthReason::kNone;
};

struct PoseStatus {
  TrackingState state = TrackingState::kUnspecified;
  uint32_t active_modalities = 0;           // modalities that constrained the estimate recently
  std::vector<std::string> active_sensors;  // their sensor names
  /// Every configured sensor's health when the pose was emitted (a Session's poses; empty from
  /// a Frontend alone), in configuration order.
  std::vector<SensorHealthStatus> sensor_health;
  /// The spec allows claiming reliable localization only with two or more modalities.
  bool localization_reliable() const { return active_modalities >= 2; }
};

/// A rigid transform stored as it travels on the wire (the quaternion is kept as given).
struct Pose {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Quaterniond orientation = Eigen::Quaterniond::Identity();
  /// Requires a unit orientation (validate() first).
  SE3 to_se3() const { return {SO3::from_quaternion_normalized(orientation), position}; }
  static Pose from_se3(const SE3& pose) { return {pose.translation(), pose.rotation().quaternion()}; }
};

/// The frame names of every pose the engine emits (stored trajectories carry them too).
inline constexpr std::string_view kWorldFrame = "world";
inline constexpr std::string_view kBodyFrame = "body";

struct PoseEstimate {
  Timestamp timestamp;
  std::string frame_id;        // world frame (ENU)
  std::string child_frame_id;  // body frame (FLU)
  Pose T_world_body;
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();  // m/s, world frame
  /// Covariance of (position error in world [m], orientation error d in the body frame [rad],
  /// R_true = R_estimate Exp(d)).
  std::optional<Matrix6d> pose_covariance;
  PoseStatus status;
};

struct Keyframe {
  uint64_t keyframe_id = 0;
  Timestamp timestamp;
  Pose T_world_body;
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  std::optional<Matrix6d> pose_covariance;  // as in PoseEstimate
  /// Relative motion since the previous keyframe (absent for the first keyframe):
  /// T_previous_current and the covariance of its SE3 tangent (rho, phi), right perturbation.
  uint64_t previous_keyframe_id = 0;
  std::optional<Pose> T_previous_current;
  std::optional<Matrix6d> relative_covariance;
};

}  // namespace hanzo::fusion::msgs
