// Global localization in a known map, no initial guess: hanzo-fusion's MapLocalizer (2D branch
// and bound over all headings and cells, 3D refinement, free-space check) against Open3D 0.16's
// global registration (FPFH + RANSAC + point-to-plane ICP), same data, same run.
//
//  - warehouse: the simulated warehouse_robot drive (VLP-16). The map: its first 20 s of sweeps
//    placed by the ground truth (deskewed per point), 0.2 m voxels (as a session's map). Queries:
//    sweeps at 22, 26, 30, 34 and 38 s (deskewed to their middle), not part of the map.
//  - real pair: small_gicp's outdoor scan pair (../shared/data/lidar_small_gicp): the target
//    scan is the "map", the source scan the query, small_gicp's transform the truth.
//
// Each engine prepares the map once (BM_*_PrepareMap: MapLocalizer::create / Open3D's normals
// and FPFH of the map) and answers queries (BM_*_Localize: everything from the query's points).
// Counters: found (answered within 0.5 m and 2 deg of the truth), wrong (answered farther
// off), refused (MapLocalizer refuses an ambiguous or unverified query; Open3D always answers),
// error_cm / error_deg (mean over the answered queries), map_points. BM_Hanzo_Localize/*/1:
// with a guess 1 m / 10 deg off, searched within 3 m / 0.5 rad. The orientation handed to MapLocalizer is the
// truth's roll and pitch with a wrong heading (a levelled IMU knows no more); Open3D gets none.

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include <benchmark/benchmark.h>
#include <fmt/format.h>

#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/lidar/map_localization.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "lidar_peers.hpp"

namespace {

using namespace hanzo::fusion;

struct Query {
  cloud::PointCloud points;  // sensor frame
  SE3 T_map_sensor;          // truth
};

struct Dataset {
  cloud::PointCloud map;
  std::vector<Query> queries;
  lidar::LidarOdometryConfig odometry;  // the registration settings a session would use there
  double open3d_voxel = 0.5;
};

SE3 interpolate(const sim::SplineTrajectory& trajectory, Timestamp time, const SE3& T_body_lidar) {
  return trajectory.sample(time).T_world_body * T_body_lidar;
}

const Dataset& warehouse() {
  static const Dataset dataset = [] {
    sim::Scenario scenario = sim::load_scenario("examples/scenarios/warehouse_robot.yaml").value();
    std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& s) { return s.modality != config::SensorModality::kLidar; });
    scenario.duration = 40.0;
    scenario.num_threads = 0;
    const calib::Calibration calibration = sim::scenario_calibration(scenario);
    const SE3 T_body_lidar = calibration.find(scenario.sensors.front().name)->T_body_sensor();
    auto simulation = sim::ScenarioSimulation::create(scenario).value();
    const sim::SplineTrajectory& trajectory = simulation->trajectory();
    const Timestamp start = trajectory.start_time();
    Dataset out;
    out.odometry.map.voxel_size = 0.5;  // indoor settings
    out.odometry.source_voxel_size = 0.25;
    out.open3d_voxel = 0.25;
    cloud::PointCloud map;
    std::vector<double> query_times = {22, 26, 30, 34, 38};
    const Status status = simulation->run([&](const sim::ScenarioSensor&, msgs::SensorMessage&& message) -> Status {
      const auto* sweep = std::get_if<msgs::PointCloudMessage>(&message);
      if (sweep == nullptr || sweep->point_timestamps.size() != sweep->points.size()) return ok_status();
      const double t = (sweep->timestamp - start).seconds();
      if (t < 20.0) {
        for (std::size_t i = 0; i < sweep->points.size(); ++i) {
          map.positions.push_back((interpolate(trajectory, sweep->point_timestamps[i], T_body_lidar) * sweep->points[i].cast<double>()).cast<float>());
        }
        return ok_status();
      }
      if (query_times.empty() || t < query_times.front()) return ok_status();
      query_times.erase(query_times.begin());
      const Timestamp middle = sweep->timestamp + Duration::from_seconds(0.05);
      const SE3 T_middle_world = interpolate(trajectory, middle, T_body_lidar).inverse();
      Query query;
      for (std::size_t i = 0; i < sweep->points.size(); ++i) {
        const SE3 T = T_middle_world * interpolate(trajectory, sweep->point_timestamps[i], T_body_lidar);
        query.points.positions.push_back((T * sweep->points[i].cast<double>()).cast<float>());
      }
      query.T_map_sensor = T_middle_world.inverse();
      out.queries.push_back(std::move(query));
      return ok_status();
    });
    if (!status) throw std::runtime_error(status.error().message);
    out.map = cloud::voxel_downsample(map, 0.2);
    return out;
  }();
  return dataset;
}

const Dataset& real_pair() {
  static const Dataset dataset = [] {
    const std::string dir = std::string(HANZO_DATA_DIR) + "/lidar_small_gicp/";
    auto source = cloud::read_cloud(dir + "source.ply");
    auto target = cloud::read_cloud(dir + "target.ply");
    if (!source || !target) throw std::runtime_error("cannot read the scan pair in " + dir);
    std::ifstream in(dir + "T_target_source.txt");
    Eigen::Matrix4d matrix;
    for (int i = 0; i < 16; ++i) in >> matrix(i / 4, i % 4);
    Dataset out;
    out.map = cloud::voxel_downsample(*target, 0.2);
    out.queries.push_back({*source, SE3::from_matrix(matrix)});
    return out;
  }();
  return dataset;
}

const Dataset& dataset(int index) { return index == 0 ? warehouse() : real_pair(); }
const char* dataset_name(int index) { return index == 0 ? "warehouse" : "real_pair"; }

// `estimates[i]`: the answer to query i, none when the engine refused it.
void report(benchmark::State& state, const Dataset& data, const std::vector<std::optional<SE3>>& estimates) {
  double translation = 0.0, rotation = 0.0;
  int found = 0, wrong = 0, answered = 0;
  for (std::size_t i = 0; i < estimates.size(); ++i) {
    if (!estimates[i]) continue;
    const SE3 error = data.queries[i].T_map_sensor.inverse() * *estimates[i];
    ++answered;
    translation += error.translation().norm();
    rotation += error.rotation().log().norm();
    if (error.translation().norm() < 0.5 && error.rotation().log().norm() < 2.0 * M_PI / 180.0) ++found;
    else ++wrong;
  }
  const double n = static_cast<double>(std::max(1, answered));
  state.counters["error_cm"] = 100.0 * translation / n;  // over the answered queries
  state.counters["error_deg"] = rotation / n * 180.0 / M_PI;
  state.counters["found"] = found;    // answered within 0.5 m and 2 deg
  state.counters["wrong"] = wrong;    // answered farther off
  state.counters["refused"] = static_cast<double>(estimates.size()) - answered;
  state.counters["map_points"] = static_cast<double>(data.map.size());
  state.SetLabel(dataset_name(static_cast<int>(state.range(0))));
}

lidar::MapLocalizer make_localizer(const Dataset& data) {
  auto localizer = lidar::MapLocalizer::create(data.map.positions, {}, data.odometry);
  if (!localizer) throw std::runtime_error(localizer.error().message);
  return std::move(localizer).value();
}

void BM_Hanzo_PrepareMap(benchmark::State& state) {
  const Dataset& data = dataset(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(make_localizer(data));
  state.counters["map_points"] = static_cast<double>(data.map.size());
  state.SetLabel(dataset_name(static_cast<int>(state.range(0))));
}

// range(1) = 1: with a guess 1 m / 10 deg off the truth, searched within 3 m / 0.5 rad.
void BM_Hanzo_Localize(benchmark::State& state) {
  const Dataset& data = dataset(static_cast<int>(state.range(0)));
  const bool guessed = state.range(1) == 1;
  const lidar::MapLocalizer localizer = make_localizer(data);
  std::vector<std::optional<SE3>> estimates;
  for (auto _ : state) {
    estimates.clear();
    for (const Query& query : data.queries) {
      const SO3 wrong_heading = SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 2.0) * query.T_map_sensor.rotation();
      lidar::MapLocalizationQuery window;
      if (guessed) {
        window.T_map_sensor_guess = query.T_map_sensor * SE3(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 0.17), Eigen::Vector3d(0.8, -0.6, 0.0));
        window.linear_window = 3.0;
        window.angular_window = 0.5;
      }
      auto found = localizer.localize(query.points.positions, wrong_heading, window);
      if (std::getenv("HANZO_BENCH_VERBOSE")) {
        std::fprintf(stderr, "truth (%.1f, %.1f): %s\n", query.T_map_sensor.translation().x(), query.T_map_sensor.translation().y(),
                     found ? fmt::format("({:.2f}, {:.2f}), candidate {}, RMSE {:.3f}, {} nodes, {} headings, {:.0f} ms",
                                         found->T_map_sensor.translation().x(), found->T_map_sensor.translation().y(), found->candidate_rank,
                                         found->inlier_rmse, found->nodes_evaluated, found->headings, 1e3 * found->seconds).c_str()
                           : found.error().message.c_str());
      }
      estimates.push_back(found ? std::optional<SE3>(found->T_map_sensor) : std::nullopt);
    }
  }
  report(state, data, estimates);
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(data.queries.size()));
}

void BM_Open3d_PrepareMap(benchmark::State& state) {
  const Dataset& data = dataset(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(bench::open3d_prepare_global(cloud::voxel_downsample(data.map, data.open3d_voxel), data.open3d_voxel));
  state.counters["map_points"] = static_cast<double>(data.map.size());
  state.SetLabel(dataset_name(static_cast<int>(state.range(0))));
}

void BM_Open3d_Localize(benchmark::State& state) {
  const Dataset& data = dataset(static_cast<int>(state.range(0)));
  const auto target = bench::open3d_prepare_global(cloud::voxel_downsample(data.map, data.open3d_voxel), data.open3d_voxel);
  std::vector<std::optional<SE3>> estimates;
  for (auto _ : state) {
    estimates.clear();
    for (const Query& query : data.queries) {
      estimates.push_back(bench::open3d_global_register(cloud::voxel_downsample(query.points, data.open3d_voxel), *target, data.open3d_voxel)
                              .T_target_source);
    }
  }
  report(state, data, estimates);
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(data.queries.size()));
}

BENCHMARK(BM_Hanzo_PrepareMap)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_Hanzo_Localize)->Args({0, 0})->Args({1, 0})->Args({0, 1})->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_Open3d_PrepareMap)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_Open3d_Localize)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace

BENCHMARK_MAIN();
