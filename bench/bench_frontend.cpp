// Frontend filters: per-IMU propagation and per-update cost of the EKF (block-sparse), the
// same EKF written densely (DenseEkfReference), the UKF and the particle filter; replay
// throughput of robot_localization's bag 2 through a Frontend.

#include <chrono>
#include <cstdio>
#include <filesystem>

#include <benchmark/benchmark.h>

#include "dense_ekf_reference.hpp"
#include "hanzo/fusion/estimate/attitude_models.hpp"
#include "hanzo/fusion/estimate/error_state_ekf.hpp"
#include "hanzo/fusion/estimate/particle_filter.hpp"
#include "hanzo/fusion/estimate/position_models.hpp"
#include "hanzo/fusion/estimate/unscented_kalman_filter.hpp"
#include "hanzo/fusion/estimate/velocity_models.hpp"
#include "hanzo/fusion/io/rosbag_import.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/pipeline/frontend.hpp"

namespace hanzo::fusion {
namespace {

using namespace estimate;

FilterConfig filter_config() {
  FilterConfig config;
  config.imu_mounting = {SO3::exp(Eigen::Vector3d(0.01, -0.02, 0.03)), Eigen::Vector3d(0.1, 0.0, 0.05)};
  config.imu_noise.sample_interval = 0.005;
  return config;
}

NavigationState start_state() {
  NavigationState state;
  state.velocity = Eigen::Vector3d(5.0, 0.5, 0.0);
  state.R_world_body = SO3::exp(Eigen::Vector3d(0.02, -0.01, 1.0));
  return state;
}

ErrorCovariance start_covariance() {
  ErrorVector sigmas;
  sigmas << 0.5, 0.5, 0.5, 0.02, 0.02, 0.1, 0.2, 0.2, 0.2, 0.05, 0.05, 0.05, 0.002, 0.002, 0.002, 1e-6, 1e-6, 0.01, 0.0, 0.0, 0.0;
  return sigmas.array().square().matrix().asDiagonal();
}

// A varying IMU sample so nothing is constant-folded.
ImuSample sample_at(int64_t k) {
  const double phase = static_cast<double>(k % 1000) * 0.01;
  return {Timestamp::from_nanoseconds(k * 5'000'000), Eigen::Vector3d(0.01 * std::sin(phase), 0.02, 0.1 * std::cos(phase)),
          Eigen::Vector3d(0.3 * std::cos(phase), 0.1, 9.81)};
}

void BM_EkfPredict(benchmark::State& state) {
  ErrorStateEkf ekf(filter_config());
  ekf.reset(start_state(), start_covariance());
  int64_t k = 0;
  for (auto _ : state) {
    ekf.predict(sample_at(k++), 0.005);
    benchmark::DoNotOptimize(ekf);
  }
}
BENCHMARK(BM_EkfPredict);

void BM_DenseEkfPredict(benchmark::State& state) {
  const FilterConfig config = filter_config();
  bench::DenseEkfReference ekf(config.imu_mounting, config.imu_noise);
  ekf.reset(start_state(), start_covariance());
  int64_t k = 0;
  for (auto _ : state) {
    ekf.predict(sample_at(k++), 0.005);
    benchmark::DoNotOptimize(ekf);
  }
}
BENCHMARK(BM_DenseEkfPredict);

void BM_UkfPredict(benchmark::State& state) {
  UnscentedKalmanFilter ukf(filter_config(), UkfConfig{});
  ukf.reset(start_state(), start_covariance());
  int64_t k = 0;
  for (auto _ : state) {
    ukf.predict(sample_at(k++), 0.005);
    benchmark::DoNotOptimize(ukf);
  }
}
BENCHMARK(BM_UkfPredict);

void BM_ParticlePredict(benchmark::State& state) {
  ParticleFilter filter(filter_config(), ParticleFilterConfig{static_cast<int>(state.range(0)), 0.5, 1});
  filter.reset(start_state(), start_covariance());
  int64_t k = 0;
  for (auto _ : state) {
    filter.predict(sample_at(k++), 0.005);
    benchmark::DoNotOptimize(filter);
  }
}
BENCHMARK(BM_ParticlePredict)->Arg(1000)->Unit(benchmark::kMicrosecond);

// The measurement models of a typical update, 3 to 6 dimensions.
template <typename Model>
Model make_model();
template <>
GnssPositionModel make_model() { return {Eigen::Vector3d(0.1, 0.2, 0.0), Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.3, 0.0, 1.0)}; }
template <>
WheelOdometryModel make_model() {
  WheelOdometryMeasurement m;
  m.forward_speed = 5.0;
  return {m, SE3(), GyroReading{}};
}
template <>
ImuAttitudeModel make_model() { return {SO3::exp(Eigen::Vector3d(0.02, -0.01, 1.0)), Eigen::Matrix3d::Identity() * 1e-4, SO3(), {true, true, true}}; }
template <>
PoseModel make_model() { return {SE3(SO3::exp(Eigen::Vector3d(0.02, -0.01, 1.0)), Eigen::Vector3d(0.1, 0.0, 0.0)), Eigen::Matrix<double, 6, 6>::Identity() * 0.01, SE3()}; }

template <typename Model>
void BM_EkfUpdate(benchmark::State& state) {
  // Repeated updates with the gate off: the cost does not depend on the values.
  ErrorStateEkf ekf(filter_config());
  ekf.reset(start_state(), start_covariance());
  const Model model = make_model<Model>();
  for (auto _ : state) benchmark::DoNotOptimize(ekf.update(model, false));
}
BENCHMARK(BM_EkfUpdate<GnssPositionModel>);
BENCHMARK(BM_EkfUpdate<WheelOdometryModel>);
BENCHMARK(BM_EkfUpdate<ImuAttitudeModel>);
BENCHMARK(BM_EkfUpdate<PoseModel>);

void BM_DenseEkfUpdatePose(benchmark::State& state) {
  const FilterConfig config = filter_config();
  bench::DenseEkfReference ekf(config.imu_mounting, config.imu_noise);
  ekf.reset(start_state(), start_covariance());
  const PoseModel model = make_model<PoseModel>();
  for (auto _ : state) {
    ekf.update(model);
    benchmark::DoNotOptimize(ekf);
  }
}
BENCHMARK(BM_DenseEkfUpdatePose);

template <typename Model>
void BM_UkfUpdate(benchmark::State& state) {
  UnscentedKalmanFilter ukf(filter_config(), UkfConfig{});
  ukf.reset(start_state(), start_covariance());
  const Model model = make_model<Model>();
  for (auto _ : state) benchmark::DoNotOptimize(ukf.update(model, false));
}
BENCHMARK(BM_UkfUpdate<GnssPositionModel>);
BENCHMARK(BM_UkfUpdate<PoseModel>);

void BM_ParticleUpdateGnss(benchmark::State& state) {
  ParticleFilter filter(filter_config(), ParticleFilterConfig{static_cast<int>(state.range(0)), 0.0001, 1});
  filter.reset(start_state(), start_covariance());
  const GnssPositionModel model = make_model<GnssPositionModel>();
  for (auto _ : state) benchmark::DoNotOptimize(filter.update(model, false));
}
BENCHMARK(BM_ParticleUpdateGnss)->Arg(1000)->Unit(benchmark::kMicrosecond);

// Replay of robot_localization's bag 2 (61.2 s, 6121 messages) through a Frontend.
std::string bag2_log() {
  const std::string log = (std::filesystem::temp_directory_path() / "hanzo_bench_bag2.mcap").string();
  io::SensorLogWriterConfig writer_config;
  writer_config.foxglove_channels = false;
  auto writer = io::SensorLogWriter::open(log, writer_config).value();
  io::RosbagImportConfig config;
  config.topic_map = {{"/imu/data", "/imu"}, {"/jackal_velocity_controller/odom", "/wheels"}};
  config.wheel_separation = 0.37;
  if (!io::import_rosbag(HANZO_DATA_DIR "/robot_localization/test2.bag", *writer, config).ok()) std::abort();
  if (!writer->close().ok()) std::abort();
  return log;
}

void BM_ReplayBag2(benchmark::State& state) {
  static const std::string log = bag2_log();
  config::FusionConfig config = config::load_fusion_config(HANZO_SOURCE_DIR "/examples/robot_localization/bag2_ekf.yaml").value();
  config.frontend.type = static_cast<config::FrontendType>(state.range(0));
  std::vector<std::pair<std::string, msgs::SensorMessage>> messages;
  auto reader = io::SensorLogReader::open(log).value();
  io::LogEntry entry;
  while (reader->next(entry).value()) messages.emplace_back(entry.topic == "/imu" ? "imu" : "wheels", std::get<msgs::SensorMessage>(entry.message));
  double seconds = 0.0;
  for (auto _ : state) {
    auto session = pipeline::Frontend::create(config, {}).value();
    const auto start = std::chrono::steady_clock::now();
    for (const auto& [sensor, message] : messages) benchmark::DoNotOptimize(session->push(sensor, message));
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  state.counters["realtime_factor"] = 61.2 * static_cast<double>(state.iterations()) / seconds;
  state.counters["us_per_message"] = 1e6 * seconds / static_cast<double>(state.iterations() * messages.size());
  state.SetLabel(std::string(config::to_string(config.frontend.type)));
}
BENCHMARK(BM_ReplayBag2)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ReplayBag2)->Arg(2)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace
}  // namespace hanzo::fusion

BENCHMARK_MAIN();
