#pragma once
// Per-sensor health of a Session (spec: degraded mode per modality): whether each configured
// sensor constrains the estimate now, and if not, why. A sensor that is not ok has its
// measurements (and so its factors) left out until it recovers; the others carry on.
//
//   ok        its latest measurements were fused
//   degraded  it streams, but its latest measurements were not used as they came: gated (the
//             chi-square gate refused them), no_fix (GNSS below the configured min_fix: an
//             outage, a tunnel), degenerate_geometry (a LiDAR sweep constrains only
//             some directions, e.g. a corridor), weather (rain, fog: phantom returns, short range),
//             slip (wheels disagree with the LiDAR odometry), not_registered (LiDAR sweeps failed
//             to register)
//   lost      timeout (silent for longer than its timeout), not_fused (nothing fuses this
//             modality, e.g. cameras before visual odometry)

#include <string>
#include <string_view>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/time.hpp"
#include "hanzo/fusion/msgs/estimate_messages.hpp"

namespace hanzo::fusion::pipeline {

// The states and reasons travel in PoseEstimate.status (msgs), hence defined there.
using msgs::HealthReason;
using msgs::HealthState;
using msgs::to_string;

struct SensorHealth {
  std::string sensor;
  config::SensorModality modality = config::SensorModality::kImu;
  HealthState state = HealthState::kOk;
  HealthReason reason = HealthReason::kNone;
};

/// A change of one sensor's health, at a time of the data (body clock).
struct HealthChange {
  Timestamp time;
  SensorHealth health;
};

}  // namespace hanzo::fusion::pipeline
