#pragma once
// Why a message was not fused: the input checks that refuse a message in push() (returned in a
// PushStatus) and the fusion outcomes that are only counted (SensorStatistics::rejected). Each
// has a stable snake_case name, used in summaries, JSON and error messages ("too_late: ...").
//
//   input checks       unknown_sensor, wrong_type, invalid, duplicate, out_of_order,
//                      future_dated, too_late
//   fusion outcomes    gated, numerical_failure, no_fix, weak_fix, spike, gimbal_lock, gap,
//                      no_ego_velocity, heading_unknown, slip (wheels that disagree with the
//                      LiDAR), not_registered (a LiDAR sweep that did not register),
//                      registration_behind (a live sweep dropped: the registration was busy),
//                      imu_behind (a sweep dropped while waiting for the IMU), tracking_lost (a
//                      camera frame the visual odometry could not track: dark, glare, motion
//                      blur or too few features; the health names which)
//   informational      aligning, before_initialization, reference (the first wheel reading),
//                      merged (a wheel reading too soon after the previous one to difference:
//                      the next reading differences over both), not_fused (a modality nothing
//                      fuses, e.g. cameras)

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>

#include "hanzo/fusion/core/result.hpp"

namespace hanzo::fusion::pipeline {

enum class Rejection : uint8_t {
  kUnknownSensor,
  kWrongType,
  kInvalid,
  kDuplicate,
  kOutOfOrder,
  kFutureDated,
  kTooLate,
  kGated,
  kNumericalFailure,
  kNoFix,
  kWeakFix,
  kSpike,
  kGimbalLock,
  kGap,
  kNoEgoVelocity,
  kHeadingUnknown,
  kSlip,
  kNotRegistered,
  kRegistrationBehind,
  kImuBehind,
  kAligning,
  kBeforeInitialization,
  kReference,
  kMerged,
  kNotFused,
  kTrackingLost,
};

std::string_view to_string(Rejection rejection);
std::optional<Rejection> rejection_from_string(std::string_view name);
/// Whether the rejection is one of push()'s input checks (the message was refused, nothing
/// changed) rather than a fusion outcome.
bool is_input_check(Rejection rejection);
/// Counts by reason, keyed by the reasons' names (for JSON, text and metrics labels).
std::map<std::string, uint64_t> by_name(const std::map<Rejection, uint64_t>& counts);

/// What push() says: ok, or the input check that refused the message and why (for people:
/// error().message is "<reason>: <detail>"). Converts to Status for code that needs no reason.
class [[nodiscard]] PushStatus {
 public:
  PushStatus() = default;
  PushStatus(Rejection reason, const std::string& detail);

  bool ok() const { return !reason_; }
  explicit operator bool() const { return ok(); }
  /// The rejection; requires !ok().
  Rejection reason() const { return *reason_; }
  /// Requires !ok().
  const Error& error() const { return error_; }
  operator Status() const { return ok() ? ok_status() : Status(error_); }  // NOLINT: implicit by design

 private:
  std::optional<Rejection> reason_;
  Error error_;
};

}  // namespace hanzo::fusion::pipeline
