// Bundle adjustment the size of the visual-inertial keyframe graph after the whole simulated
// drone flight (about 80 keyframes, 2400 landmarks, 22000 projections): hanzo-fusion's batch
// optimizer with graph::ProjectionFactor and the vision module's dedicated Schur-complement
// solver (vision::bundle_adjust, the visual odometry's local bundle adjustment) against the same
// problem written the usual way with Ceres directly (an AutoDiffCostFunction reprojection error,
// quaternion manifold), with sparse normal Cholesky and with Ceres' own Schur complement
// (SPARSE_SCHUR, the points eliminated first). Same settings otherwise: Levenberg-Marquardt from
// a trust region of 1e4, Huber at 1.345 sigma, one thread, at most 50 iterations; the first two
// poses fixed.
//
// The scene: a camera on a circle of radius 6 m looking outward at points on a wall 12-14 m from
// the centre, 1 px pixel noise; the poses start 5 cm / 0.6 degrees off, the points 0.2 m off.
// Each run starts from the same values and includes building the problem. Counters:
// pose_rmse_m (after), iterations.

#include <benchmark/benchmark.h>
#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <cmath>
#include <random>
#include <vector>

#include "hanzo/fusion/core/pinhole_camera.hpp"
#include "hanzo/fusion/core/se3.hpp"
#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/graph/projection_factors.hpp"
#include "hanzo/fusion/vision/bundle_adjustment.hpp"

namespace {

using namespace hanzo::fusion;

constexpr int kPoses = 80;
constexpr int kPoints = 2400;
constexpr int kMaxViews = 10;  // consecutive keyframes that see a point
constexpr double kPixelSigma = 1.0;
constexpr double kHuber = 1.345;

struct Observation {
  int pose = 0;
  int point = 0;
  Eigen::Vector2d pixel;
};

struct BundleProblem {
  PinholeCamera camera;  // 752 x 480 pixels
  SE3 T_body_camera;  // camera z along the body's x (forward), camera x to the body's right
  std::vector<SE3> poses_true, poses_start;
  std::vector<Eigen::Vector3d> points_true, points_start;
  std::vector<Observation> observations;
};

const BundleProblem& bundle_problem() {
  static const BundleProblem problem = [] {
    BundleProblem p;
    p.camera.fx = p.camera.fy = 460.0;
    p.camera.cx = 376.0;
    p.camera.cy = 240.0;
    p.T_body_camera = SE3(SO3::from_matrix((Eigen::Matrix3d() << 0, 0, 1, -1, 0, 0, 0, -1, 0).finished()), Eigen::Vector3d::Zero());
    std::mt19937 rng(7);
    std::normal_distribution<double> normal(0.0, 1.0);
    std::uniform_real_distribution<double> angle(0.0, 2.0 * M_PI), radius(12.0, 14.0), height(-2.0, 4.0);
    for (int i = 0; i < kPoses; ++i) {
      const double heading = 2.0 * M_PI * i / kPoses;
      const SE3 truth(SO3::exp({0.0, 0.0, heading}), Eigen::Vector3d(6.0 * std::cos(heading), 6.0 * std::sin(heading), 1.0 + 0.3 * std::sin(3 * heading)));
      p.poses_true.push_back(truth);
      const bool gauge = i < 2;
      p.poses_start.push_back(gauge ? truth
                                    : SE3(truth.rotation() * SO3::exp(0.01 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng))),
                                          truth.translation() + 0.05 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng))));
    }
    for (int j = 0; j < kPoints; ++j) {
      const double a = angle(rng), r = radius(rng);
      const Eigen::Vector3d point(r * std::cos(a), r * std::sin(a), height(rng));
      int views = 0;
      for (int i = 0; i < kPoses && views < kMaxViews; ++i) {
        const int k = (static_cast<int>(a / (2.0 * M_PI) * kPoses) - kMaxViews / 2 + i + kPoses) % kPoses;  // start near the point
        const Eigen::Vector3d p_camera = (p.poses_true[k] * p.T_body_camera).inverse() * point;
        const std::optional<Eigen::Vector2d> pixel = p.camera.project(p_camera);
        if (!pixel || pixel->x() < 0 || pixel->y() < 0 || pixel->x() >= 752 || pixel->y() >= 480) continue;
        p.observations.push_back({k, j, *pixel + kPixelSigma * Eigen::Vector2d(normal(rng), normal(rng))});
        ++views;
      }
      p.points_true.push_back(point);
      p.points_start.push_back(point + 0.2 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng)));
    }
    return p;
  }();
  return problem;
}

double pose_rmse(const BundleProblem& p, const std::vector<Eigen::Vector3d>& positions) {
  double squared = 0.0;
  for (int i = 0; i < kPoses; ++i) squared += (positions[static_cast<size_t>(i)] - p.poses_true[static_cast<size_t>(i)].translation()).squaredNorm();
  return std::sqrt(squared / kPoses);
}

void BM_BundleAdjustment_Hanzo(benchmark::State& state) {
  const BundleProblem& p = bundle_problem();
  graph::FactorGraph graph;
  const graph::GaussianNoise noise = graph::GaussianNoise::from_sigmas(Eigen::Vector2d::Constant(kPixelSigma)).value();
  for (const Observation& o : p.observations) {
    graph.emplace_robust<graph::ProjectionFactor>(graph::RobustKernel{graph::RobustKernel::Type::kHuber, kHuber}, graph::X(static_cast<uint64_t>(o.pose)),
                                                  graph::L(static_cast<uint64_t>(o.point)), o.pixel, p.camera, p.T_body_camera, noise);
  }
  graph::BatchOptimizerConfig config;
  config.max_iterations = 50;
  config.initial_trust_region_radius = 1e4;
  config.fixed = {graph::X(0), graph::X(1)};
  graph::OptimizationSummary summary;
  std::vector<Eigen::Vector3d> positions;
  for (auto _ : state) {
    graph::Values values;
    for (int i = 0; i < kPoses; ++i) values.insert(graph::X(static_cast<uint64_t>(i)), p.poses_start[static_cast<size_t>(i)]);
    for (int j = 0; j < kPoints; ++j) values.insert(graph::L(static_cast<uint64_t>(j)), p.points_start[static_cast<size_t>(j)]);
    summary = graph::optimize(graph, values, config).value();
    positions.clear();
    for (int i = 0; i < kPoses; ++i) positions.push_back(values.at<SE3>(graph::X(static_cast<uint64_t>(i))).value().translation());
  }
  state.counters["projections"] = static_cast<double>(p.observations.size());
  state.counters["iterations"] = summary.iterations;
  state.counters["pose_rmse_m"] = pose_rmse(p, positions);
}
BENCHMARK(BM_BundleAdjustment_Hanzo)->Unit(benchmark::kMillisecond)->Iterations(3);

void BM_BundleAdjustment_HanzoSchur(benchmark::State& state) {
  const BundleProblem& p = bundle_problem();
  vision::BundleAdjustmentConfig config;
  config.max_iterations = 50;
  config.initial_trust_region_radius = 1e4;
  config.huber_threshold = kHuber;
  vision::BundleAdjustmentSummary summary;
  std::vector<Eigen::Vector3d> positions;
  for (auto _ : state) {
    vision::BundleProblem problem;
    problem.cameras.push_back({p.camera, p.T_body_camera});
    problem.T_world_body = p.poses_start;
    for (int i = 0; i < kPoses; ++i) problem.pose_fixed.push_back(i < 2);
    problem.points_world = p.points_start;
    for (const Observation& o : p.observations) problem.observations.push_back({o.pose, o.point, 0, o.pixel, kPixelSigma});
    summary = vision::bundle_adjust(problem, config).value();
    positions.clear();
    for (const SE3& pose : problem.T_world_body) positions.push_back(pose.translation());
  }
  state.counters["projections"] = static_cast<double>(p.observations.size());
  state.counters["iterations"] = summary.iterations;
  state.counters["pose_rmse_m"] = pose_rmse(p, positions);
}
BENCHMARK(BM_BundleAdjustment_HanzoSchur)->Unit(benchmark::kMillisecond)->Iterations(3);

// The usual hand-written Ceres reprojection error: pose as a unit quaternion (x, y, z, w) and a
// translation, T_world_body; the point in the world.
struct ReprojectionError {
  Eigen::Vector2d pixel;
  const BundleProblem* problem = nullptr;
  template <typename T>
  bool operator()(const T* q_world_body, const T* t_world_body, const T* point, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q(q_world_body);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t(t_world_body), p_world(point);
    const Eigen::Matrix<T, 3, 1> p_body = q.conjugate() * (p_world - t);
    const Eigen::Matrix<T, 3, 1> p_camera =
        problem->T_body_camera.rotation().matrix().transpose().cast<T>() * (p_body - problem->T_body_camera.translation().cast<T>());
    const PinholeCamera& c = problem->camera;
    residual[0] = (c.fx * p_camera.x() / p_camera.z() + c.cx - pixel.x()) / kPixelSigma;
    residual[1] = (c.fy * p_camera.y() / p_camera.z() + c.cy - pixel.y()) / kPixelSigma;
    return true;
  }
};

// Argument: 0 sparse normal Cholesky, 1 Ceres' Schur complement (SPARSE_SCHUR).
void BM_BundleAdjustment_CeresAutoDiff(benchmark::State& state) {
  const BundleProblem& p = bundle_problem();
  ceres::Solver::Options options;
  options.minimizer_type = ceres::TRUST_REGION;
  options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  options.linear_solver_type = state.range(0) == 0 ? ceres::SPARSE_NORMAL_CHOLESKY : ceres::SPARSE_SCHUR;
  options.initial_trust_region_radius = 1e4;
  options.max_num_iterations = 50;
  options.num_threads = 1;
  ceres::Solver::Summary summary;
  std::vector<Eigen::Vector3d> positions;
  for (auto _ : state) {
    std::vector<Eigen::Quaterniond> rotations;
    std::vector<Eigen::Vector3d> translations, points = p.points_start;
    for (const SE3& pose : p.poses_start) {
      rotations.push_back(pose.rotation().quaternion());
      translations.push_back(pose.translation());
    }
    ceres::Problem problem;
    for (const Observation& o : p.observations) {
      auto* cost = new ceres::AutoDiffCostFunction<ReprojectionError, 2, 4, 3, 3>(new ReprojectionError{o.pixel, &p});
      problem.AddResidualBlock(cost, new ceres::HuberLoss(kHuber), rotations[static_cast<size_t>(o.pose)].coeffs().data(),
                               translations[static_cast<size_t>(o.pose)].data(), points[static_cast<size_t>(o.point)].data());
    }
    for (auto& rotation : rotations) problem.SetManifold(rotation.coeffs().data(), new ceres::EigenQuaternionManifold);
    for (int i = 0; i < 2; ++i) {
      problem.SetParameterBlockConstant(rotations[static_cast<size_t>(i)].coeffs().data());
      problem.SetParameterBlockConstant(translations[static_cast<size_t>(i)].data());
    }
    ceres::Solve(options, &problem, &summary);
    positions = translations;
  }
  state.counters["projections"] = static_cast<double>(p.observations.size());
  state.counters["iterations"] = static_cast<double>(summary.iterations.size() - 1);
  state.counters["pose_rmse_m"] = pose_rmse(p, positions);
}
BENCHMARK(BM_BundleAdjustment_CeresAutoDiff)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace

BENCHMARK_MAIN();
