#include "hanzo/fusion/pipeline/rejection.hpp"

#include <array>
#include <utility>

#include <fmt/format.h>

namespace hanzo::fusion::pipeline {
namespace {

constexpr std::array<std::pair<Rejection, std::string_view>, 26> kNames{{
    {Rejection::kUnknownSensor, "unknown_sensor"},
    {Rejection::kWrongType, "wrong_type"},
    {Rejection::kInvalid, "invalid"},
    {Rejection::kDuplicate, "duplicate"},
    {Rejection::kOutOfOrder, "out_of_order"},
    {Rejection::kFutureDated, "future_dated"},
    {Rejection::kTooLate, "too_late"},
    {Rejection::kGated, "gated"},
    {Rejection::kNumericalFailure, "numerical_failure"},
    {Rejection::kNoFix, "no_fix"},
    {Rejection::kWeakFix, "weak_fix"},
    {Rejection::kSpike, "spike"},
    {Rejection::kGimbalLock, "gimbal_lock"},
    {Rejection::kGap, "gap"},
    {Rejection::kNoEgoVelocity, "no_ego_velocity"},
    {Rejection::kHeadingUnknown, "heading_unknown"},
    {Rejection::kSlip, "slip"},
    {Rejection::kNotRegistered, "not_registered"},
    {Rejection::kRegistrationBehind, "registration_behind"},
    {Rejection::kImuBehind, "imu_behind"},
    {Rejection::kAligning, "aligning"},
    {Rejection::kBeforeInitialization, "before_initialization"},
    {Rejection::kReference, "reference"},
    {Rejection::kMerged, "merged"},
    {Rejection::kNotFused, "not_fused"},
    {Rejection::kTrackingLost, "tracking_lost"},
}};

}  // namespace

std::string_view to_string(Rejection rejection) {
  for (const auto& [value, name] : kNames) {
    if (value == rejection) return name;
  }
  return "invalid_rejection";
}

std::optional<Rejection> rejection_from_string(std::string_view name) {
  for (const auto& [value, text] : kNames) {
    if (text == name) return value;
  }
  return std::nullopt;
}

bool is_input_check(Rejection rejection) { return rejection <= Rejection::kTooLate; }

std::map<std::string, uint64_t> by_name(const std::map<Rejection, uint64_t>& counts) {
  std::map<std::string, uint64_t> named;
  for (const auto& [reason, count] : counts) named[std::string(to_string(reason))] = count;
  return named;
}

PushStatus::PushStatus(Rejection reason, const std::string& detail)
    : reason_(reason), error_(fmt::format("{}: {}", to_string(reason), detail)) {}

}  // namespace hanzo::fusion::pipeline
