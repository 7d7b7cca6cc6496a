#pragma once
// Test helper: a simulated scenario pushed through a Session, the emitted poses (10 Hz) with
// the truth at their times.

#include <gtest/gtest.h>

#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"

namespace hanzo::fusion::pipeline::testing {

struct ReplayedTrajectories {
  io::Trajectory estimate;  ///< real-time poses, at most one per 0.1 s
  io::Trajectory truth;     ///< the scenario's body pose at the same times
};

/// Every message `simulation` makes, with its sensor's name, in the order it makes them.
inline std::vector<std::pair<std::string, msgs::SensorMessage>> record(sim::ScenarioSimulation& simulation) {
  std::vector<std::pair<std::string, msgs::SensorMessage>> messages;
  EXPECT_TRUE(simulation.run([&messages](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) {
    messages.emplace_back(sensor.name, std::move(message));
    return ok_status();
  }).ok());
  return messages;
}

/// Runs `simulation` into `session` (push errors are counted by the session, not failures here)
/// and flushes it.
inline ReplayedTrajectories replay(sim::ScenarioSimulation& simulation, Session& session) {
  ReplayedTrajectories out;
  session.set_pose_callback([&](const msgs::PoseEstimate& pose) {
    if (out.estimate.size() > 0 && (pose.timestamp - out.estimate.timestamps.back()).seconds() < 0.1) return;
    out.estimate.timestamps.push_back(pose.timestamp);
    out.estimate.poses.push_back(pose.T_world_body.to_se3().matrix());
    out.truth.timestamps.push_back(pose.timestamp);
    out.truth.poses.push_back(simulation.trajectory().sample(pose.timestamp).T_world_body.matrix());
  });
  EXPECT_TRUE(simulation.run([&](const sim::ScenarioSensor& sensor, msgs::SensorMessage&& message) -> Status {
    (void)session.push(sensor.name, std::move(message));
    return ok_status();
  }).ok());
  session.flush();
  return out;
}

/// The session's optimized trajectory and the scenario's body pose at the same times.
inline ReplayedTrajectories optimized_with_truth(const Session& session, const sim::ScenarioSimulation& simulation) {
  ReplayedTrajectories out;
  for (const StampedPose& pose : session.optimized_trajectory()) {
    out.estimate.timestamps.push_back(pose.timestamp);
    out.estimate.poses.push_back(pose.T_world_body.matrix());
    out.truth.timestamps.push_back(pose.timestamp);
    out.truth.poses.push_back(simulation.trajectory().sample(pose.timestamp).T_world_body.matrix());
  }
  return out;
}

}  // namespace hanzo::fusion::pipeline::testing
