// 2D laser scan matching and SLAM on the real Intel Research Lab log
// (../shared/data/laser2d_carmen), same machine, same run:
//   - consecutive-scan matching (every 10th pair, 0.55 m / 18 deg apart on average), started
//     0.1 m / 3 deg off the logged corrected relative pose: our point-to-line ICP vs PCL's and
//     Open3D's point-to-point ICP on the same points (z = 0). Time per pair (target preparation
//     included) and the median error against the logged relative pose (itself a SLAM result: a
//     few centimetres is the floor).
//   - the whole log through PlanarLaserSlam with 5 % / 2 deg/m corrupted odometry: scans per
//     second and APE RMSE.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/io/carmen_import.hpp"
#include "hanzo/fusion/lidar/planar_icp.hpp"
#include "hanzo/fusion/pipeline/planar_laser_slam.hpp"
#include "hanzo/fusion/sim/planar_odometry_error.hpp"
#include "lidar_peers.hpp"

namespace {

using namespace hanzo::fusion;

const io::CarmenLog& intel() {
  static const io::CarmenLog log = [] {
    auto read = io::read_carmen(std::string(HANZO_DATA_DIR) + "/laser2d_carmen/intel-corrected.log.gz", {});
    if (!read) throw std::runtime_error(read.error().message);
    return std::move(*read);
  }();
  return log;
}

lidar::PlanarPoints planar_points(size_t i) {
  lidar::PlanarPoints points;
  for (const Eigen::Vector3f& p : intel().scans[i].points) points.emplace_back(p.x(), p.y());
  return points;
}

cloud::PointCloud cloud_of(size_t i) {
  cloud::PointCloud cloud;
  cloud.positions = intel().scans[i].points;
  return cloud;
}

SE2 logged(size_t i) { return io::planar_pose(intel().report.scan_poses.poses[i]); }

// Pair k: scan 10k + 1 (source) onto scan 10k (target).
constexpr size_t kPairStride = 10;
size_t pair_count() { return (intel().scans.size() - 1) / kPairStride; }
SE2 true_relative(size_t k) { return logged(kPairStride * k).inverse() * logged(kPairStride * k + 1); }
SE2 guess_of(size_t k) { return true_relative(k) * SE2(3.0 * M_PI / 180.0, {0.1, -0.05}); }

double median(std::vector<double> values) {
  std::nth_element(values.begin(), values.begin() + static_cast<long>(values.size() / 2), values.end());
  return values[values.size() / 2];
}

// ms_per_pair from the iteration time the benchmark measured (mean over iterations).
void report(benchmark::State& state, const std::vector<SE2>& estimates, double seconds) {
  std::vector<double> translation_cm, rotation_deg;
  for (size_t k = 0; k < estimates.size(); ++k) {
    const SE2 error = true_relative(k).inverse() * estimates[k];
    translation_cm.push_back(100.0 * error.translation().norm());
    rotation_deg.push_back(std::abs(error.angle()) * 180.0 / M_PI);
  }
  state.counters["pairs"] = static_cast<double>(estimates.size());
  state.counters["ms_per_pair"] = 1e3 * seconds / static_cast<double>(state.iterations()) / static_cast<double>(estimates.size());
  state.counters["median_error_cm"] = median(translation_cm);
  state.counters["median_error_deg"] = median(rotation_deg);
}

void BM_PlanarIcp(benchmark::State& state) {
  std::vector<SE2> estimates(pair_count());
  double seconds = 0.0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    for (size_t k = 0; k < pair_count(); ++k) {
      auto target = lidar::PlanarTarget::create(planar_points(kPairStride * k));
      auto result = target ? lidar::align_planar(planar_points(kPairStride * k + 1), *target, guess_of(k)) : Result<lidar::PlanarIcpResult>(target.error());
      estimates[k] = result ? result->T_target_source : guess_of(k);
    }
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  report(state, estimates, seconds);
}

void BM_PeerIcp(benchmark::State& state, bool use_pcl) {
  std::vector<SE2> estimates(pair_count());
  double seconds = 0.0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    for (size_t k = 0; k < pair_count(); ++k) {
      // The peers take no initial guess: move the source by the guess first, then compose.
      cloud::PointCloud source = cloud_of(kPairStride * k + 1);
      const SE2 guess = guess_of(k);
      for (Eigen::Vector3f& p : source.positions) {
        const Eigen::Vector2d moved = guess * Eigen::Vector2d(p.x(), p.y());
        p = Eigen::Vector3f(static_cast<float>(moved.x()), static_cast<float>(moved.y()), 0.0F);
      }
      const bench::PeerResult result = use_pcl ? bench::pcl_register(bench::PeerMethod::kIcp, source, cloud_of(kPairStride * k), 0.3, 1.0)
                                               : bench::open3d_register(bench::PeerMethod::kIcp, source, cloud_of(kPairStride * k), 0.3);
      const Eigen::Matrix4d T = result.T_target_source.matrix();
      estimates[k] = io::planar_pose(T) * guess;
    }
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  report(state, estimates, seconds);
}

void BM_PlanarLaserSlamIntel(benchmark::State& state) {
  std::vector<SE2> truth;
  for (size_t i = 0; i < intel().scans.size(); ++i) truth.push_back(logged(i));
  const std::vector<SE2> odometry = sim::corrupt_planar_odometry(truth, {});
  io::Trajectory trajectory;
  for (auto _ : state) {
    pipeline::PlanarLaserSlam slam;
    for (size_t i = 0; i < truth.size(); ++i) (void)slam.add_scan(intel().scans[i], odometry[i]);
    (void)slam.finish();
    trajectory = slam.trajectory();
    state.counters["loop_closures"] = static_cast<double>(slam.summary().loop_closures);
  }
  auto ape = eval::compute_ape(intel().report.scan_poses, trajectory, {.relation = eval::PoseRelation::kTranslation, .alignment = eval::Alignment::kSE3});
  state.counters["scans"] = static_cast<double>(trajectory.size());
  state.counters["ape_rmse_m"] = ape ? ape->statistics.rmse : -1.0;
  state.counters["scans_per_s"] = benchmark::Counter(static_cast<double>(trajectory.size()), benchmark::Counter::kIsIterationInvariantRate);
}

}  // namespace

BENCHMARK(BM_PlanarIcp)->Name("hanzo/planar_icp/intel_pairs")->Unit(benchmark::kMillisecond)->MinTime(0.5);
BENCHMARK_CAPTURE(BM_PeerIcp, pcl, true)->Name("pcl/icp/intel_pairs")->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK_CAPTURE(BM_PeerIcp, open3d, false)->Name("open3d/icp/intel_pairs")->Unit(benchmark::kMillisecond)->Iterations(2);
BENCHMARK(BM_PlanarLaserSlamIntel)->Name("hanzo/slam2d/intel")->Unit(benchmark::kSecond)->Iterations(1);
BENCHMARK_MAIN();
