#include "hanzo/fusion/sim/scenario.hpp"

#include <algorithm>
#include <cmath>

namespace hanzo::fusion::sim {

double ScenarioSensor::rate_hz() const {
  return std::visit([](const auto& config) { return config.rate_hz; }, simulator);
}

void set_seed(Scenario& scenario, uint64_t seed) {
  scenario.seed = seed;
  uint64_t index = 0;
  for (ScenarioSensor& sensor : scenario.sensors) {
    const uint64_t sensor_seed = seed * 1000003ULL + ++index;
    std::visit([sensor_seed](auto& config) { config.seed = sensor_seed; }, sensor.simulator);
  }
}

Result<SplineTrajectory> make_trajectory(const Scenario& scenario) {
  switch (scenario.trajectory_type) {
    case TrajectoryType::kGroundVehicle: return with_context(make_ground_trajectory(scenario.start_time, scenario.ground_path), "trajectory");
    case TrajectoryType::kDrone: return with_context(make_drone_trajectory(scenario.start_time, scenario.drone), "trajectory");
    case TrajectoryType::kHandheld: return with_context(make_handheld_trajectory(scenario.start_time, scenario.handheld), "trajectory");
    case TrajectoryType::kStations: return with_context(make_stations_trajectory(scenario.start_time, scenario.stations), "trajectory");
  }
  return Error{"trajectory: unknown type"};
}

Timestamp scenario_end_time(const Scenario& scenario, const SplineTrajectory& trajectory) {
  if (!scenario.duration) return trajectory.end_time();
  return std::min(trajectory.end_time(), scenario.start_time + Duration::from_seconds(*scenario.duration));
}

Timestamp scenario_log_start_time(const Scenario& scenario) { return scenario.start_time + Duration::from_seconds(scenario.log_start); }

calib::Calibration scenario_calibration(const Scenario& scenario) {
  calib::Calibration calibration;
  for (const ScenarioSensor& sensor : scenario.sensors) {
    calib::SensorCalibration entry = calib::SensorCalibration::from_transform(sensor.name, sensor.T_body_sensor);
    if (const auto* camera = std::get_if<CameraSimulatorConfig>(&sensor.simulator)) {
      entry.camera = calib::CameraCalibration{camera->intrinsics, camera->distortion};
    }
    calibration.sensors.push_back(std::move(entry));
  }
  return calibration;
}

config::FusionConfig scenario_fusion_config(const Scenario& scenario) {
  config::FusionConfig fusion;
  for (const ScenarioSensor& sensor : scenario.sensors) {
    config::SensorConfig entry;
    entry.name = sensor.name;
    entry.modality = sensor.modality;
    entry.topic = sensor.topic;
    entry.rate_hz = sensor.rate_hz();
    entry.body_frame = sensor.name + "_link";
    if (const auto* imu = std::get_if<ImuSimulatorConfig>(&sensor.simulator); imu && fusion.find_sensor(sensor.name) == nullptr) {
      config::CovarianceConfig& covariance = fusion.frontend.covariance;
      covariance.process_noise_accel = imu->process_noise_accel;
      covariance.process_noise_gyro = imu->process_noise_gyro;
      covariance.accel_bias_random_walk = imu->accel_bias_random_walk;
      covariance.gyro_bias_random_walk = imu->gyro_bias_random_walk;
      fusion.frontend.predict_rate_hz = imu->rate_hz;
    }
    if (const auto* lidar = std::get_if<LidarSimulatorConfig>(&sensor.simulator)) {
      // The preset the pattern came from, by its ring count and columns.
      for (LidarModel model : {LidarModel::kVelodyneVlp16, LidarModel::kVelodyneHdl64, LidarModel::kOusterOs1_64, LidarModel::kPlanarLaser}) {
        const LidarPattern preset = LidarPattern::preset(model);
        if (preset.elevations == lidar->pattern.elevations && preset.columns == lidar->pattern.columns) entry.type = to_string(model);
      }
    }
    if (const auto* camera = std::get_if<CameraSimulatorConfig>(&sensor.simulator);
        camera != nullptr && (camera->encoding == msgs::ImageEncoding::kDepth16 || camera->encoding == msgs::ImageEncoding::kDepth32f)) {
      entry.type = config::kDepthCameraType;
    }
    // The world frame of the simulation is ENU at the scenario's datum: GNSS fixes must be
    // converted with the same datum to land in it.
    if (sensor.modality == config::SensorModality::kGnss) fusion.frontend.datum = scenario.datum;
    fusion.sensors.push_back(std::move(entry));
  }
  // The frontend that fuses the rig best: cameras with an IMU and no LiDAR are a
  // visual-inertial rig (the MSCKF: 0.27 m against the EKF's 1.98 m on ar_handheld, 0.036 m
  // against 0.113 m on the drone; bench/RESULTS.md); with a LiDAR the EKF fuses its odometry.
  const auto has = [&](config::SensorModality modality) {
    return std::any_of(scenario.sensors.begin(), scenario.sensors.end(), [&](const ScenarioSensor& s) { return s.modality == modality; });
  };
  if (has(config::SensorModality::kCamera) && has(config::SensorModality::kImu) && !has(config::SensorModality::kLidar)) {
    fusion.frontend.type = config::FrontendType::kMsckf;
  }
  return fusion;
}

}  // namespace hanzo::fusion::sim
