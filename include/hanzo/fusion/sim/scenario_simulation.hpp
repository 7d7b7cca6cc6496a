#pragma once
// ScenarioSimulation: runs a Scenario, producing every sensor's messages merged in timestamp
// order (ties in sensor order), as a recorded log would hold them.
//
// Each sensor samples at its rate from the log's start (scenario_log_start_time) to the
// scenario's end (scenario_end_time);
// a LiDAR sweep is stamped at its start and needs the whole sweep inside the trajectory.
// Messages a sensor cannot produce are left out and counted (a LiDAR sweep that saw
// nothing); GNSS outages still produce NO_FIX messages as receivers do.
// Deterministic: the same scenario (seed included) gives the same messages byte for byte, for
// any Scenario::num_threads (LiDARs and cameras cast their rays on that many threads; the
// sensors themselves run one after another). The statistics say how much each sensor produced
// and how long its simulation took.

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/msgs/sensor_messages.hpp"
#include "hanzo/fusion/sim/scenario.hpp"

namespace hanzo::fusion::sim {

struct SensorRunStatistics {
  std::string name;
  std::string modality;
  std::size_t messages = 0;
  std::size_t skipped = 0;          ///< messages left out (nothing seen)
  std::size_t elements = 0;         ///< points (LiDAR), pixels (camera), targets (radar), else messages
  double simulation_seconds = 0.0;  ///< wall-clock seconds spent simulating this sensor
};

/// The true IMU biases at one IMU sample.
struct ImuBiasTruth {
  Timestamp timestamp;
  Eigen::Vector3d accel_bias = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero();
};

class ScenarioSimulation {
 public:
  /// Receives each message with its sensor; an error stops the run and is returned by run().
  using Sink = std::function<Status(const ScenarioSensor& sensor, msgs::SensorMessage&& message)>;

  /// Builds the world, trajectory and sensor simulators; fails on an invalid trajectory,
  /// datum or camera configuration, naming the sensor.
  static Result<std::unique_ptr<ScenarioSimulation>> create(Scenario scenario);
  ~ScenarioSimulation();

  Status run(const Sink& sink);

  const Scenario& scenario() const { return scenario_; }
  const SplineTrajectory& trajectory() const { return trajectory_; }
  const World& world() const { return world_; }
  Timestamp end_time() const;
  const std::vector<SensorRunStatistics>& statistics() const { return statistics_; }
  /// Filled by run() from the first IMU (unless turned off: 11 kB per second of a 200 Hz IMU,
  /// which a long run that does not write the truth need not keep).
  const std::vector<ImuBiasTruth>& imu_bias_truth() const { return imu_bias_truth_; }
  void set_record_imu_bias_truth(bool record) { record_imu_bias_truth_ = record; }
  /// The ground truth of the points of a LiDAR's sweep that run() gave the sink last (valid
  /// inside the sink and until that LiDAR's next sweep): per point, the object it hit
  /// (LidarSimulator::last_object_ids). Empty for another sensor or before its first sweep.
  const std::vector<int>& lidar_object_ids(const std::string& sensor) const;

 private:
  struct Stream;
  ScenarioSimulation(Scenario scenario, SplineTrajectory trajectory);

  Scenario scenario_;
  SplineTrajectory trajectory_;
  World world_;
  std::vector<std::unique_ptr<Stream>> streams_;
  std::vector<SensorRunStatistics> statistics_;
  std::vector<ImuBiasTruth> imu_bias_truth_;
  bool record_imu_bias_truth_ = true;
};

}  // namespace hanzo::fusion::sim
