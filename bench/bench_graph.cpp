// Pose-graph optimization on SE-Sync's benchmark files (../shared/data/pose_graph/SOURCE.md),
// SE-Sync's (chordal) objective, one iteration each (seconds, not milliseconds):
// 1. hanzo, Levenberg-Marquardt on Ceres with sparse Cholesky, from the file's vertices.
// 2. hanzo from the chordal initialization (graph/chordal_initialization.hpp), its time included.
// 3. Open3D 0.16's GlobalOptimization (Levenberg-Marquardt) from the file's vertices on the same
//    edges (2D graphs lifted to 3D). Open3D solves a DENSE 6N x 6N system, so it runs only on the
//    two smallest sets: at 1000 poses it already takes 12 s and 650 MB; manhattan (3500 poses)
//    would need a 3.5 GB matrix and minutes per iteration, city10000 29 GB.
// 4. hanzo's IncrementalSmoother fed pose by pose in file order (new poses from odometry): the
//    time of each update plus reading back the latest pose, p50 / p99 / max in milliseconds, the
//    latest estimate's gap right after the last update, and the gap once the background batch
//    has finished (wait_for_batch, timed separately as final_batch_s).
// 5. hanzo's global-optimality certificate (graph/optimality_certificate.hpp) of the chordal-start
//    optimum: refinement plus the certificate matrix's Cholesky tests; no peer offers one
//    (GTSAM, g2o, Ceres, Open3D). Counters: certified (1/0), min_eigenvalue.
// Counters: objective = SE-Sync's objective reached, gap = objective / f* - 1 (f* published by
// SE-Sync), iterations (hanzo), initialization_s (chordal start).

#include <algorithm>
#include <chrono>
#include <map>

#include <benchmark/benchmark.h>
#include <fmt/format.h>

#include "graph_peers.hpp"
#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/chordal_initialization.hpp"
#include "hanzo/fusion/graph/g2o_io.hpp"
#include "hanzo/fusion/graph/incremental_smoother.hpp"
#include "hanzo/fusion/graph/optimality_certificate.hpp"

namespace {

using namespace hanzo::fusion;

struct DataSet {
  const char* file;
  double optimum;  // SE-Sync's published f* (more digits where SOURCE.md reproduces them: intel, manhattan)
};
constexpr DataSet kDataSets[] = {{"intel", 52.3482},           {"manhattan", 6431.42},         {"city10000", 638.6},
                                 {"sphere2500", 1687.0},       {"parking-garage", 1.263}};

const graph::PoseGraph& pose_graph(int index) {
  static std::map<int, graph::PoseGraph> cache;
  auto found = cache.find(index);
  if (found == cache.end()) {
    const std::string path = fmt::format("{}/pose_graph/se_sync/{}.g2o", HANZO_DATA_DIR, kDataSets[index].file);
    found = cache.emplace(index, graph::read_g2o(path).value()).first;
  }
  return found->second;
}

void report(benchmark::State& state, int index, const graph::Values& values) {
  const double objective = graph::se_sync_objective(pose_graph(index), values).value();
  state.counters["objective"] = objective;
  state.counters["gap"] = objective / kDataSets[index].optimum - 1.0;
  state.SetLabel(kDataSets[index].file);
}

void BM_HanzoBatch(benchmark::State& state, bool chordal_start) {
  const auto index = static_cast<int>(state.range(0));
  const graph::PoseGraph& input = pose_graph(index);
  const graph::FactorGraph factors = input.factor_graph(graph::PoseGraph::Objective::kChordal).value();
  graph::BatchOptimizerConfig config;
  config.fixed = input.fixed;
  graph::Values values;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    values = chordal_start ? graph::chordal_initialization(input).value() : input.initial;
    state.counters["initialization_s"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const graph::OptimizationSummary summary = graph::optimize(factors, values, config).value();
    state.counters["iterations"] = summary.iterations;
  }
  report(state, index, values);
}
void BM_HanzoFromFile(benchmark::State& state) { BM_HanzoBatch(state, false); }
void BM_HanzoFromChordal(benchmark::State& state) { BM_HanzoBatch(state, true); }
BENCHMARK(BM_HanzoFromFile)->DenseRange(0, 4)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();
BENCHMARK(BM_HanzoFromChordal)->DenseRange(0, 4)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

void BM_Certificate(benchmark::State& state) {
  const auto index = static_cast<int>(state.range(0));
  const graph::PoseGraph& input = pose_graph(index);
  graph::Values values = graph::chordal_initialization(input).value();
  graph::BatchOptimizerConfig config;
  config.fixed = input.fixed;
  graph::optimize(input.factor_graph(graph::PoseGraph::Objective::kChordal).value(), values, config).value();
  graph::OptimalityCertificate certificate;
  for (auto _ : state) certificate = graph::certify_global_optimality(input, values).value();
  state.counters["certified"] = certificate.certified ? 1.0 : 0.0;
  state.counters["min_eigenvalue"] = certificate.min_eigenvalue;
  state.counters["iterations"] = certificate.refinement_iterations;
  report(state, index, certificate.refined);
}
BENCHMARK(BM_Certificate)->DenseRange(0, 4)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

void BM_Incremental(benchmark::State& state) {
  const auto index = static_cast<int>(state.range(0));
  const graph::PoseGraph& input = pose_graph(index);
  const std::vector<graph::GraphUpdate> updates = input.incremental_updates(graph::PoseGraph::Objective::kChordal).value();
  std::vector<double> milliseconds;
  double latest_gap = 0.0, final_batch_seconds = 0.0;
  graph::Values values;
  for (auto _ : state) {
    graph::IncrementalSmootherConfig config;
    config.batch.fixed = input.fixed;
    graph::IncrementalSmoother smoother(config);
    milliseconds.clear();
    for (const graph::GraphUpdate& update : updates) {
      const auto start = std::chrono::steady_clock::now();
      if (!smoother.update(update.factors, update.values).ok()) state.SkipWithError("update failed");
      const graph::Key newest = update.values.all().rbegin()->first;
      benchmark::DoNotOptimize(smoother.estimate().all().at(newest));
      milliseconds.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count());
    }
    latest_gap = graph::se_sync_objective(input, smoother.estimate()).value() / kDataSets[index].optimum - 1.0;
    const auto start = std::chrono::steady_clock::now();
    if (!smoother.wait_for_batch().ok()) state.SkipWithError("final batch failed");
    final_batch_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    values = smoother.estimate();
    state.counters["batches_merged"] = smoother.batches_merged();
  }
  std::vector<double> sorted = milliseconds;
  std::sort(sorted.begin(), sorted.end());
  const auto percentile = [&](double p) { return sorted[static_cast<std::size_t>(p * static_cast<double>(sorted.size() - 1))]; };
  state.counters["updates"] = static_cast<double>(sorted.size());
  state.counters["p50_ms"] = percentile(0.5);
  state.counters["p99_ms"] = percentile(0.99);
  state.counters["max_ms"] = sorted.back();
  state.counters["latest_gap"] = latest_gap;
  state.counters["final_batch_s"] = final_batch_seconds;
  report(state, index, values);
}
BENCHMARK(BM_Incremental)->Arg(2)->Arg(1)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

// The graph as Open3D's 4x4 poses and edges; information reordered to (rotation, translation),
// 3D rotation information converted from g2o's quaternion error to the rotation vector (x 1/4),
// 2D graphs lifted to 3D with the yaw information on roll, pitch and z as well.
Eigen::Matrix4d matrix_of(const graph::Value& pose) {
  if (const auto* se3 = std::get_if<SE3>(&pose)) return se3->matrix();
  const SE2& se2 = std::get<SE2>(pose);
  Eigen::Matrix4d matrix = Eigen::Matrix4d::Identity();
  matrix.topLeftCorner<2, 2>() = se2.rotation_matrix();
  matrix.block<2, 1>(0, 3) = se2.translation();
  return matrix;
}

void BM_Open3d(benchmark::State& state) {
  const auto index = static_cast<int>(state.range(0));
  const graph::PoseGraph& input = pose_graph(index);
  std::map<graph::Key, int> node;
  std::vector<Eigen::Matrix4d> initial;
  for (graph::Key key : input.vertices) {
    node[key] = static_cast<int>(initial.size());
    initial.push_back(matrix_of(input.initial.all().at(key)));
  }
  std::vector<bench::Open3dEdge> edges;
  for (const graph::PoseGraphEdge& edge : input.edges) {
    Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Zero();
    if (input.dimension == 3) {
      const Eigen::MatrixXd& g2o = edge.information;  // (translation, quaternion vector)
      information.topLeftCorner<3, 3>() = 0.25 * g2o.bottomRightCorner(3, 3);
      information.bottomRightCorner<3, 3>() = g2o.topLeftCorner(3, 3);
      information.topRightCorner<3, 3>() = 0.5 * g2o.bottomLeftCorner(3, 3);
      information.bottomLeftCorner<3, 3>() = 0.5 * g2o.topRightCorner(3, 3);
    } else {
      const Eigen::MatrixXd& g2o = edge.information;  // (x, y, theta)
      const int map[3] = {3, 4, 2};
      for (int r = 0; r < 3; ++r) {
        for (int c = 0; c < 3; ++c) information(map[r], map[c]) = g2o(r, c);
      }
      information(0, 0) = information(1, 1) = information(5, 5) = g2o(2, 2);
    }
    edges.push_back({node.at(edge.from), node.at(edge.to), matrix_of(edge.measurement), information});
  }
  std::vector<Eigen::Matrix4d> poses;
  for (auto _ : state) {
    poses = initial;
    bench::open3d_optimize_pose_graph(poses, edges);
  }
  graph::Values values;
  for (graph::Key key : input.vertices) {
    const Eigen::Matrix4d& pose = poses[static_cast<std::size_t>(node.at(key))];
    if (input.dimension == 3) {
      values.insert(key, SE3(SO3::from_matrix(pose.topLeftCorner<3, 3>()), pose.block<3, 1>(0, 3)));
    } else {
      values.insert(key, SE2(std::atan2(pose(1, 0), pose(0, 0)), pose.block<2, 1>(0, 3)));
    }
  }
  report(state, index, values);
}
BENCHMARK(BM_Open3d)->Arg(0)->Arg(4)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
