#pragma once
// Scenario: everything a simulation run needs, loaded from a scenario YAML file
// (examples/scenarios/*.yaml; full reference: docs/simulator.md):
//
//   scenario:
//     name: warehouse_robot
//     seed: 7                      # every noise draw follows from it
//     start_time: 1700000000.0     # seconds since the Unix epoch of the first sample
//     datum: {latitude: 47.3769, longitude: 8.5417, altitude: 408.0}   # WGS84 of world ENU origin
//     ground_truth_rate: 200       # Hz of the TUM ground truth
//     threads: 1                   # ray-casting threads (0: all cores); same output for any count
//     log_start: 0                 # seconds into the trajectory the log begins (> 0: a start in motion)
//     world: {ground: ..., boxes: [...], cylinders: [...], walls: [...], people: [...], city: {...}}
//     trajectory: {type: ground_vehicle | drone | handheld | stations, ...}
//     sensors:
//       imu: {rate: 200, to_body: {translation: [...], rotation: [w, x, y, z]}, process_noise_accel: ...}
//       lidar: {model: velodyne_vlp16, rate: 10, ...}
//     faults:
//       - {type: rain, sensor: lidar, start: 20, end: 30}
//
// Sensor modality comes from the name as in the fusion configuration (imu*, lidar*, camera*,
// gnss*/gps*, wheel*/odom*, radar*) unless `modality:` says. Fault and people times are
// seconds after start_time. Unknown keys are errors; every error names file, line and key.

#include <cstdint>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/geodesy.hpp"
#include "hanzo/fusion/core/result.hpp"
#include "hanzo/fusion/sim/camera_simulator.hpp"
#include "hanzo/fusion/sim/drone_trajectory.hpp"
#include "hanzo/fusion/sim/gnss_simulator.hpp"
#include "hanzo/fusion/sim/ground_path.hpp"
#include "hanzo/fusion/sim/handheld_trajectory.hpp"
#include "hanzo/fusion/sim/imu_simulator.hpp"
#include "hanzo/fusion/sim/lidar_simulator.hpp"
#include "hanzo/fusion/sim/radar_simulator.hpp"
#include "hanzo/fusion/sim/range_simulator.hpp"
#include "hanzo/fusion/sim/stations_trajectory.hpp"
#include "hanzo/fusion/sim/wheel_odometry_simulator.hpp"
#include "hanzo/fusion/sim/world.hpp"

namespace hanzo::fusion::sim {

using SensorSimulatorConfig = std::variant<ImuSimulatorConfig, LidarSimulatorConfig, CameraSimulatorConfig,
                                           GnssSimulatorConfig, WheelOdometrySimulatorConfig, RadarSimulatorConfig, RangeSimulatorConfig>;

struct ScenarioSensor {
  std::string name;                 ///< the key under `sensors:`; calibration "<name>_to_body"
  config::SensorModality modality = config::SensorModality::kImu;
  std::string topic;                ///< default "/sensors/<name>"
  SE3 T_body_sensor;                ///< also set inside `simulator`
  SensorSimulatorConfig simulator;  ///< its rate, noise, faults and seed

  double rate_hz() const;
};

enum class TrajectoryType { kGroundVehicle, kDrone, kHandheld, kStations };

struct Scenario {
  std::string name;
  uint64_t seed = 1;
  Timestamp start_time = Timestamp::from_nanoseconds(1'700'000'000'000'000'000);
  GeodeticPoint datum{47.3769, 8.5417, 408.0};
  double ground_truth_rate_hz = 200.0;
  int num_threads = 1;  ///< ray-casting threads of LiDARs and cameras (0: all cores); output is the same for any count
  std::optional<double> duration;  ///< seconds simulated; default (and at most): the whole trajectory
  /// Seconds after start_time at which the sensors (and the ground truth) begin: the log of a
  /// vehicle already moving, as a recording started mid-drive. Fault times stay relative to
  /// start_time.
  double log_start = 0.0;
  WorldDescription world;
  TrajectoryType trajectory_type = TrajectoryType::kGroundVehicle;
  GroundPathConfig ground_path;      ///< trajectory_type kGroundVehicle
  DroneTrajectoryConfig drone;       ///< kDrone
  HandheldTrajectoryConfig handheld; ///< kHandheld
  StationsTrajectoryConfig stations; ///< kStations
  std::vector<ScenarioSensor> sensors;
};

Result<Scenario> load_scenario(const std::string& path);
/// source_name stands in for the file name in error messages.
Result<Scenario> parse_scenario(const std::string& yaml_text, const std::string& source_name);

/// Sets the scenario seed and derives every sensor's seed from it (seed * 1000003 + sensor
/// number, counting from 1 in file order), as the loader does.
void set_seed(Scenario& scenario, uint64_t seed);

/// The body trajectory the scenario describes.
Result<SplineTrajectory> make_trajectory(const Scenario& scenario);
/// start_time + duration, or the trajectory's end when sooner or no duration is given.
Timestamp scenario_end_time(const Scenario& scenario, const SplineTrajectory& trajectory);
/// start_time + log_start: the first sample of every sensor and of the ground truth.
Timestamp scenario_log_start_time(const Scenario& scenario);
/// The calibration file of the spec for the scenario's sensors (cameras with intrinsics).
calib::Calibration scenario_calibration(const Scenario& scenario);
/// A fusion configuration that runs the scenario's log: its sensors, topics and rates, and the
/// IMU noise of the simulated IMU.
config::FusionConfig scenario_fusion_config(const Scenario& scenario);

}  // namespace hanzo::fusion::sim
