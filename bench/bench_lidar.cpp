// Registration speed and accuracy on the real scan pair of small_gicp / fast_gicp
// (../shared/data/lidar_small_gicp, about 70k points each), same machine, same run:
// hanzo-fusion's ICP / point-to-plane ICP / GICP / NDT against PCL 1.13 and Open3D 0.16.
//
// Each case starts from the clouds voxel-downsampled at 0.1 / 0.25 / 0.5 m and identity as the
// initial guess, and its time includes what the library needs from there: kd-trees, normals or
// covariances (10 neighbours for every library), the NDT grid, the iterations. Maximum
// correspondence distance 1 m (0.5 m for point-to-point ICP, whose estimate is biased by far
// outliers at 1 m), at most 64 iterations, NDT cells of 1 m.
// Counters: source_points, error_cm and error_deg against small_gicp's reference transform,
// converged (1/0). hanzo-fusion runs on 1 and 2 threads; PCL and Open3D here are single-threaded
// (Open3D's ICP parallelizes with OpenMP when it has it; Debian's build runs it on all cores).

#include <cmath>
#include <fstream>
#include <map>
#include <string>

#include <benchmark/benchmark.h>

#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/lidar/registration.hpp"
#include "lidar_peers.hpp"

namespace {

using namespace hanzo::fusion;

const std::string kPairDir = std::string(HANZO_DATA_DIR) + "/lidar_small_gicp/";

struct Pair {
  cloud::PointCloud source;
  cloud::PointCloud target;
};

const SE3& reference() {
  static const SE3 value = [] {
    std::ifstream in(kPairDir + "T_target_source.txt");
    Eigen::Matrix4d matrix;
    for (int i = 0; i < 16; ++i) in >> matrix(i / 4, i % 4);
    return SE3::from_matrix(matrix);
  }();
  return value;
}

const Pair& pair_at(double voxel) {
  static std::map<double, Pair> pairs;
  auto found = pairs.find(voxel);
  if (found != pairs.end()) return found->second;
  auto source = cloud::read_cloud(kPairDir + "source.ply");
  auto target = cloud::read_cloud(kPairDir + "target.ply");
  if (!source || !target) throw std::runtime_error("cannot read the scan pair in " + kPairDir);
  return pairs[voxel] = Pair{cloud::voxel_downsample(*source, voxel), cloud::voxel_downsample(*target, voxel)};
}

void report(benchmark::State& state, const Pair& pair, const SE3& estimate, bool converged) {
  const SE3 error = reference().inverse() * estimate;
  state.counters["source_points"] = static_cast<double>(pair.source.size());
  state.counters["error_cm"] = 100.0 * error.translation().norm();
  state.counters["error_deg"] = error.rotation().log().norm() * 180.0 / M_PI;
  state.counters["converged"] = converged ? 1.0 : 0.0;
}

double correspondence_distance(bench::PeerMethod method) { return method == bench::PeerMethod::kIcp ? 0.5 : 1.0; }

void hanzo_registration(benchmark::State& state, bench::PeerMethod method, double voxel, int threads) {
  const Pair& pair = pair_at(voxel);
  lidar::RegistrationConfig config;
  config.method = static_cast<lidar::RegistrationMethod>(method);
  config.max_correspondence_distance = correspondence_distance(method);
  config.max_iterations = 64;
  config.num_threads = threads;
  Result<lidar::RegistrationResult> result = Error("not run");
  for (auto _ : state) {
    result = lidar::register_clouds(pair.source, pair.target, SE3::identity(), config);
    benchmark::DoNotOptimize(result);
  }
  if (!result) {
    state.SkipWithError(result.error().message.c_str());
    return;
  }
  report(state, pair, result->T_target_source, result->converged);
}

void peer_registration(benchmark::State& state, bool use_pcl, bench::PeerMethod method, double voxel) {
  const Pair& pair = pair_at(voxel);
  bench::PeerResult result;
  for (auto _ : state) {
    result = use_pcl ? bench::pcl_register(method, pair.source, pair.target, correspondence_distance(method), 1.0)
                     : bench::open3d_register(method, pair.source, pair.target, correspondence_distance(method));
    benchmark::DoNotOptimize(result);
  }
  report(state, pair, result.T_target_source, result.converged);
}

void register_all() {
  const std::pair<bench::PeerMethod, const char*> methods[] = {
      {bench::PeerMethod::kGicp, "gicp"}, {bench::PeerMethod::kNdt, "ndt"},
      {bench::PeerMethod::kIcpPlane, "icp_plane"}, {bench::PeerMethod::kIcp, "icp"}};
  for (double voxel : {0.25, 0.1, 0.5}) {
    for (const auto& [method, name] : methods) {
      const std::string suffix = std::string(name) + "/voxel:" + std::to_string(voxel).substr(0, 4);
      for (int threads : {1, 2}) {
        benchmark::RegisterBenchmark(("hanzo/" + suffix + "/threads:" + std::to_string(threads)).c_str(), hanzo_registration,
                                     method, voxel, threads)
            ->Unit(benchmark::kMillisecond)
            ->MinTime(0.5);
      }
      benchmark::RegisterBenchmark(("pcl/" + suffix).c_str(), peer_registration, true, method, voxel)
          ->Unit(benchmark::kMillisecond)
          ->Iterations(3);
      // Open3D has no NDT, and Debian's Open3D 0.16 aborts in GICP (an Eigen assertion inside its
      // covariance square root, EigenSolver<2x2>::eigenvectors), so it runs ICP and point-to-plane.
      if (method == bench::PeerMethod::kIcp || method == bench::PeerMethod::kIcpPlane) {
        benchmark::RegisterBenchmark(("open3d/" + suffix).c_str(), peer_registration, false, method, voxel)
            ->Unit(benchmark::kMillisecond)
            ->Iterations(3);
      }
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  register_all();
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
