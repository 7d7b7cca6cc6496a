#include "hanzo/fusion/pipeline/sensor_health.hpp"

namespace hanzo::fusion::pipeline {

std::string_view to_string(HealthState state) {
  switch (state) {
    case HealthState::kOk: return "ok";
    case HealthState::kDegraded: return "degraded";
    case HealthState::kLost: return "lost";
  }
  return "invalid";
}

std::string_view to_string(HealthReason reason) {
  switch (reason) {
    case HealthReason::kNone: return "";
    case HealthReason::kTimeout: return "timeout";
    case HealthReason::kGated: return "gated";
    case HealthReason::kNoFix: return "no_fix";
    case HealthReason::kDegenerateGeometry: return "degenerate_geometry";
    case HealthReason::kWeather: return "weather";
    case HealthReason::kSlip: return "slip";
    case HealthReason::kNotRegistered: return "not_registered";
    case HealthReason::kNotFused: return "not_fused";
  }
  return "invalid";
}

}  // namespace hanzo::fusion::pipeline
