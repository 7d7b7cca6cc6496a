#include "hanzo/fusion/sim/scenario_simulation.hpp"

#include <chrono>
#include <cmath>

namespace hanzo::fusion::sim {

struct ScenarioSimulation::Stream {
  const ScenarioSensor* sensor = nullptr;
  std::size_t statistics_index = 0;
  double rate_hz = 1.0;
  Timestamp last_start;   // the last sample time allowed
  int64_t next_index = 0; // sample k is at start + k / rate_hz
  Timestamp next;
  // Returns the message at a time, or nullopt when it is left out.
  std::function<std::optional<msgs::SensorMessage>(Timestamp)> produce;
  // A second message of the same sensor after each produced one (a camera's ground-truth
  // detections, which a detector gives after its image), or nullopt.
  std::function<std::optional<msgs::SensorMessage>()> follow_up;
  std::shared_ptr<LidarSimulator> lidar;  // a LiDAR's simulator (its last sweep's truth)
};

ScenarioSimulation::ScenarioSimulation(Scenario scenario, SplineTrajectory trajectory)
    : scenario_(std::move(scenario)), trajectory_(std::move(trajectory)), world_(scenario_.world) {}

ScenarioSimulation::~ScenarioSimulation() = default;

Timestamp ScenarioSimulation::end_time() const { return scenario_end_time(scenario_, trajectory_); }

const std::vector<int>& ScenarioSimulation::lidar_object_ids(const std::string& sensor) const {
  static const std::vector<int> none;
  for (const auto& stream : streams_) {
    if (stream->lidar && stream->sensor->name == sensor) return stream->lidar->last_object_ids();
  }
  return none;
}

Result<std::unique_ptr<ScenarioSimulation>> ScenarioSimulation::create(Scenario scenario) {
  Result<SplineTrajectory> trajectory = make_trajectory(scenario);
  if (!trajectory) return trajectory.error();
  std::unique_ptr<ScenarioSimulation> simulation(new ScenarioSimulation(std::move(scenario), std::move(*trajectory)));
  const World& world = simulation->world_;
  const SplineTrajectory& path = simulation->trajectory_;
  bool first_imu = true;
  for (const ScenarioSensor& sensor : simulation->scenario_.sensors) {
    auto stream = std::make_unique<Stream>();
    stream->sensor = &sensor;
    stream->rate_hz = sensor.rate_hz();
    stream->statistics_index = simulation->statistics_.size();
    stream->last_start = simulation->end_time();
    simulation->statistics_.push_back({sensor.name, std::string(config::to_string(sensor.modality))});
    if (const auto* imu = std::get_if<ImuSimulatorConfig>(&sensor.simulator)) {
      auto simulator = std::make_shared<ImuSimulator>(*imu);
      std::vector<ImuBiasTruth>* truth = first_imu ? &simulation->imu_bias_truth_ : nullptr;
      const bool* record = &simulation->record_imu_bias_truth_;
      first_imu = false;
      stream->produce = [simulator, &path, truth, record](Timestamp time) -> std::optional<msgs::SensorMessage> {
        ImuSample sample = simulator->measure(path, time);
        if (truth != nullptr && *record) truth->push_back({time, sample.accel_bias, sample.gyro_bias});
        return std::move(sample.message);
      };
    } else if (const auto* lidar = std::get_if<LidarSimulatorConfig>(&sensor.simulator)) {
      LidarSimulatorConfig config = *lidar;
      config.num_threads = simulation->scenario_.num_threads;
      auto simulator = std::make_shared<LidarSimulator>(config, world, path);
      stream->lidar = simulator;
      stream->last_start = simulation->end_time() - Duration::from_seconds(1.0 / lidar->rate_hz);
      stream->produce = [simulator](Timestamp time) -> std::optional<msgs::SensorMessage> {
        msgs::PointCloudMessage cloud = simulator->measure(time);
        if (cloud.points.empty()) return std::nullopt;
        return cloud;
      };
    } else if (const auto* camera = std::get_if<CameraSimulatorConfig>(&sensor.simulator)) {
      CameraSimulatorConfig config = *camera;
      config.num_threads = simulation->scenario_.num_threads;
      Result<CameraSimulator> created = CameraSimulator::create(config, world, path);
      if (!created) return with_context(Result<std::unique_ptr<ScenarioSimulation>>(created.error()), "sensors." + sensor.name);
      auto simulator = std::make_shared<CameraSimulator>(std::move(*created));
      stream->produce = [simulator](Timestamp time) -> std::optional<msgs::SensorMessage> { return simulator->measure(time); };
      if (config.ground_truth_detections != GroundTruthDetections::kNone || config.ground_truth_segmentation) {
        stream->follow_up = [simulator]() -> std::optional<msgs::SensorMessage> {
          std::optional<msgs::DetectionsMessage> detections = simulator->detections();
          if (!detections) return std::nullopt;
          return msgs::SensorMessage(std::move(*detections));
        };
      }
    } else if (const auto* gnss = std::get_if<GnssSimulatorConfig>(&sensor.simulator)) {
      Result<GnssSimulator> created = GnssSimulator::create(*gnss, path, &world);
      if (!created) return with_context(Result<std::unique_ptr<ScenarioSimulation>>(created.error()), "sensors." + sensor.name);
      auto simulator = std::make_shared<GnssSimulator>(std::move(*created));
      stream->produce = [simulator](Timestamp time) -> std::optional<msgs::SensorMessage> { return simulator->measure(time); };
    } else if (const auto* wheels = std::get_if<WheelOdometrySimulatorConfig>(&sensor.simulator)) {
      auto simulator = std::make_shared<WheelOdometrySimulator>(*wheels, path);
      stream->produce = [simulator](Timestamp time) -> std::optional<msgs::SensorMessage> { return simulator->measure(time); };
    } else if (const auto* radar = std::get_if<RadarSimulatorConfig>(&sensor.simulator)) {
      auto simulator = std::make_shared<RadarSimulator>(*radar, world, path);
      stream->produce = [simulator](Timestamp time) -> std::optional<msgs::SensorMessage> { return simulator->measure(time); };
    } else if (const auto* range = std::get_if<RangeSimulatorConfig>(&sensor.simulator)) {
      auto simulator = std::make_shared<RangeSimulator>(*range, world, path);
      stream->produce = [simulator](Timestamp time) -> std::optional<msgs::SensorMessage> { return simulator->measure(time); };
    }
    // The first sample at or after the log's start (sample k stays at start_time + k / rate).
    stream->next_index = static_cast<int64_t>(std::ceil(simulation->scenario_.log_start * stream->rate_hz - 1e-9));
    stream->next = simulation->scenario_.start_time +
                   Duration::from_nanoseconds(std::llround(static_cast<double>(stream->next_index) * 1e9 / stream->rate_hz));
    simulation->streams_.push_back(std::move(stream));
  }
  return simulation;
}

Status ScenarioSimulation::run(const Sink& sink) {
  imu_bias_truth_.clear();
  while (true) {
    Stream* earliest = nullptr;
    for (const auto& stream : streams_) {
      if (stream->next <= stream->last_start && (earliest == nullptr || stream->next < earliest->next)) earliest = stream.get();
    }
    if (earliest == nullptr) return ok_status();
    SensorRunStatistics& statistics = statistics_[earliest->statistics_index];
    const auto begin = std::chrono::steady_clock::now();
    std::optional<msgs::SensorMessage> message = earliest->produce(earliest->next);
    statistics.simulation_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
    ++earliest->next_index;
    earliest->next = scenario_.start_time +
                     Duration::from_nanoseconds(std::llround(static_cast<double>(earliest->next_index) * 1e9 / earliest->rate_hz));
    if (!message) {
      ++statistics.skipped;
      continue;
    }
    ++statistics.messages;
    if (const auto* cloud = std::get_if<msgs::PointCloudMessage>(&*message)) {
      statistics.elements += cloud->points.size();
    } else if (const auto* image = std::get_if<msgs::ImageMessage>(&*message)) {
      statistics.elements += static_cast<std::size_t>(image->width) * image->height;
    } else if (const auto* radar = std::get_if<msgs::RadarMessage>(&*message)) {
      statistics.elements += radar->targets.size();
    } else {
      ++statistics.elements;
    }
    HANZO_RETURN_IF_ERROR(sink(*earliest->sensor, std::move(*message)));
    if (earliest->follow_up) {
      if (std::optional<msgs::SensorMessage> follow_up = earliest->follow_up()) HANZO_RETURN_IF_ERROR(sink(*earliest->sensor, std::move(*follow_up)));
    }
  }
}

}  // namespace hanzo::fusion::sim
