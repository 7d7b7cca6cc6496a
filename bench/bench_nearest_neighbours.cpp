// Map nearest-neighbour structures, same machine, same run, same points: the real outdoor scan
// pair (lidar_small_gicp; target scan as the map, source points as queries, 0.1 m voxels),
// 10 nearest neighbours of every query point after moving the source onto the target.
//   hanzo Octree (incremental; built by inserting the map), hanzo KdTree (nanoflann),
//   hanzo VoxelHashMap (neighbours within one voxel edge only: 1 m voxels, so not exact beyond
//   1 m), PCL 1.13 OctreePointCloudSearch and KdTreeFLANN, Open3D 0.16 KDTreeFlann.
// Counters: build and query milliseconds, squared distance sum (equal for the exact engines).
// A second case, the sliding local map: 20 scans of the pair's target each inserted into the
// octree with 0.1 m spacing and pruned to 50 m, against rebuilding a kd-tree every scan.

#include <chrono>
#include <fstream>
#include <optional>
#include <string>

#include <benchmark/benchmark.h>

#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/cloud/kdtree.hpp"
#include "hanzo/fusion/cloud/octree.hpp"
#include "hanzo/fusion/cloud/voxel_grid.hpp"
#include "hanzo/fusion/cloud/voxel_hash_map.hpp"
#include "neighbour_peers.hpp"

namespace {

using namespace hanzo::fusion;
using Clock = std::chrono::steady_clock;
constexpr int kNeighbours = 10;

double milliseconds_since(Clock::time_point start) { return std::chrono::duration<double, std::milli>(Clock::now() - start).count(); }

struct Problem {
  std::vector<Eigen::Vector3f> map;
  std::vector<Eigen::Vector3f> queries;
};

const Problem& problem() {
  static const Problem value = [] {
    const std::string directory = std::string(HANZO_DATA_DIR) + "/lidar_small_gicp/";
    std::ifstream in(directory + "T_target_source.txt");
    Eigen::Matrix4d matrix;
    for (int i = 0; i < 16; ++i) in >> matrix(i / 4, i % 4);
    const SE3 T_target_source = SE3::from_matrix(matrix);
    auto source = cloud::read_cloud(directory + "source.ply");
    auto target = cloud::read_cloud(directory + "target.ply");
    if (!source || !target) throw std::runtime_error("cannot read the scan pair in " + directory);
    Problem out;
    out.map = cloud::voxel_downsample(*target, 0.1).positions;
    out.queries = cloud::transformed(cloud::voxel_downsample(*source, 0.1), T_target_source).positions;
    return out;
  }();
  return value;
}

void report(benchmark::State& state, const bench::NeighbourTiming& timing) {
  state.counters["map_points"] = static_cast<double>(problem().map.size());
  state.counters["queries"] = static_cast<double>(problem().queries.size());
  state.counters["build_ms"] = timing.build_ms;
  state.counters["query_ms"] = timing.query_ms;
  state.counters["distance_sum"] = timing.squared_distance_sum;
}

void BM_Octree(benchmark::State& state) {
  bench::NeighbourTiming timing;
  for (auto _ : state) {
    timing = {};
    auto start = Clock::now();
    cloud::Octree octree;
    octree.insert(problem().map);
    timing.build_ms = milliseconds_since(start);
    std::vector<Eigen::Vector3f> found;
    std::vector<float> distances;
    start = Clock::now();
    for (const Eigen::Vector3f& query : problem().queries) {
      octree.knn(query, kNeighbours, &found, &distances);
      for (const float d : distances) timing.squared_distance_sum += d;
    }
    timing.query_ms = milliseconds_since(start);
    state.counters["memory_MB"] = static_cast<double>(octree.memory_bytes()) / 1e6;
  }
  report(state, timing);
}

void BM_KdTree(benchmark::State& state) {
  bench::NeighbourTiming timing;
  for (auto _ : state) {
    timing = {};
    auto start = Clock::now();
    const cloud::KdTree tree(problem().map);
    timing.build_ms = milliseconds_since(start);
    uint32_t indices[kNeighbours];
    float distances[kNeighbours];
    start = Clock::now();
    for (const Eigen::Vector3f& query : problem().queries) {
      const std::size_t found = tree.knn(query, kNeighbours, indices, distances);
      for (std::size_t i = 0; i < found; ++i) timing.squared_distance_sum += distances[i];
    }
    timing.query_ms = milliseconds_since(start);
  }
  report(state, timing);
}

void BM_VoxelHashMap(benchmark::State& state) {
  bench::NeighbourTiming timing;
  for (auto _ : state) {
    timing = {};
    auto start = Clock::now();
    cloud::VoxelHashMap map({.voxel_size = 1.0, .max_points_per_voxel = 1 << 20, .min_point_spacing = 0.0, .max_distance = 1e6});
    map.add(problem().map, {}, Eigen::Vector3d::Zero());
    timing.build_ms = milliseconds_since(start);
    std::vector<cloud::MapPoint> found;
    start = Clock::now();
    for (const Eigen::Vector3f& query : problem().queries) {
      map.nearest_k(query, kNeighbours, 1.0F, &found);
      for (const cloud::MapPoint& point : found) timing.squared_distance_sum += (point.position - query).squaredNorm();
    }
    timing.query_ms = milliseconds_since(start);
  }
  report(state, timing);
}

void BM_Peer(benchmark::State& state, int engine) {
  bench::NeighbourTiming timing;
  for (auto _ : state) {
    switch (engine) {
      case 0: timing = bench::pcl_octree_knn(problem().map, problem().queries, kNeighbours, 0.5); break;
      case 1: timing = bench::pcl_kdtree_knn(problem().map, problem().queries, kNeighbours); break;
      default: timing = bench::open3d_kdtree_knn(problem().map, problem().queries, kNeighbours); break;
    }
  }
  report(state, timing);
}

// The sliding local map: per scan, add it (shifted 1 m further each time, as a sensor driving on)
// and prune to 50 m, then 10-NN queries of 2000 of its points; octree updated in place vs a
// kd-tree rebuilt over the kept points.
void BM_SlidingMap(benchmark::State& state, bool octree_map) {
  const std::vector<Eigen::Vector3f>& scan = problem().map;
  double update_ms = 0.0, query_ms = 0.0;
  std::size_t map_points = 0;
  for (auto _ : state) {
    update_ms = query_ms = 0.0;
    cloud::Octree octree({.min_point_spacing = 0.1});
    std::vector<Eigen::Vector3f> kept;
    for (int k = 0; k < 20; ++k) {
      const Eigen::Vector3f offset(static_cast<float>(k), 0.0F, 0.0F);
      std::vector<Eigen::Vector3f> moved(scan.size());
      for (std::size_t i = 0; i < scan.size(); ++i) moved[i] = scan[i] + offset;
      auto start = Clock::now();
      std::optional<cloud::KdTree> tree;
      if (octree_map) {
        octree.insert(moved);
        octree.remove_outside(offset, 50.0F);
      } else {
        kept.insert(kept.end(), moved.begin(), moved.end());
        std::erase_if(kept, [&](const Eigen::Vector3f& p) { return (p - offset).squaredNorm() > 2500.0F; });
        tree.emplace(kept);
      }
      update_ms += milliseconds_since(start);
      start = Clock::now();
      std::vector<Eigen::Vector3f> found;
      uint32_t indices[kNeighbours];
      float distances[kNeighbours];
      for (std::size_t i = 0; i < moved.size(); i += moved.size() / 2000) {
        if (octree_map) {
          octree.knn(moved[i], kNeighbours, &found);
        } else {
          tree->knn(moved[i], kNeighbours, indices, distances);
        }
      }
      query_ms += milliseconds_since(start);
      map_points = octree_map ? octree.size() : kept.size();
    }
  }
  state.counters["update_ms_per_scan"] = update_ms / 20.0;
  state.counters["query_ms_per_scan"] = query_ms / 20.0;
  state.counters["map_points"] = static_cast<double>(map_points);
}

}  // namespace

BENCHMARK(BM_Octree)->Name("hanzo/octree/knn10")->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_KdTree)->Name("hanzo/kdtree/knn10")->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK(BM_VoxelHashMap)->Name("hanzo/voxel_hash_map_1m/knn10_within_1m")->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK_CAPTURE(BM_Peer, pcl_octree, 0)->Name("pcl/octree_0.5m/knn10")->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK_CAPTURE(BM_Peer, pcl_kdtree, 1)->Name("pcl/kdtree_flann/knn10")->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK_CAPTURE(BM_Peer, open3d_kdtree, 2)->Name("open3d/kdtree_flann/knn10")->Unit(benchmark::kMillisecond)->Iterations(3);
BENCHMARK_CAPTURE(BM_SlidingMap, octree, true)->Name("hanzo/octree/sliding_map")->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK_CAPTURE(BM_SlidingMap, kdtree, false)->Name("hanzo/kdtree_rebuilt/sliding_map")->Unit(benchmark::kMillisecond)->Iterations(1);
BENCHMARK_MAIN();
