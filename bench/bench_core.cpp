// Core math: hanzo-fusion's SO3/SE3/geodesy against the peers on the machine, in one run.
//   hanzo/...      this project
//   eigen/...      Eigen 3.4 (AngleAxis, Quaternion, Isometry3d, unsupported MatrixFunctions)
//   geographiclib/ GeographicLib::LocalCartesian
// Run: make bench  (or build/bench/bench_core)

#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <GeographicLib/LocalCartesian.hpp>
#include <benchmark/benchmark.h>
#include <unsupported/Eigen/MatrixFunctions>

#include "hanzo/fusion/core/geodesy.hpp"
#include "hanzo/fusion/core/se3.hpp"

namespace {

using namespace hanzo::fusion;
constexpr int kCount = 1024;  // inputs cycled through so the branch predictor sees variety

std::vector<SE3::Tangent> random_twists() {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::vector<SE3::Tangent> twists(kCount);
  for (auto& xi : twists) {
    for (int k = 0; k < 6; ++k) xi[k] = uniform(rng) * (k < 3 ? 5.0 : 1.5);
  }
  return twists;
}

const std::vector<SE3::Tangent>& twists() {
  static const std::vector<SE3::Tangent> values = random_twists();
  return values;
}

Eigen::Matrix4d twist_matrix(const SE3::Tangent& xi) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Zero();
  m.topLeftCorner<3, 3>() = SO3::hat(xi.tail<3>());
  m.topRightCorner<3, 1>() = xi.head<3>();
  return m;
}

void hanzo_so3_exp(benchmark::State& state) {
  size_t i = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(SO3::exp(twists()[i++ % kCount].tail<3>()));
  }
}

void eigen_angle_axis_to_quaternion(benchmark::State& state) {
  size_t i = 0;
  for (auto _ : state) {
    const Eigen::Vector3d phi = twists()[i++ % kCount].tail<3>();
    const double angle = phi.norm();
    benchmark::DoNotOptimize(Eigen::Quaterniond(Eigen::AngleAxisd(angle, phi / angle)));
  }
}

void hanzo_so3_log(benchmark::State& state) {
  std::vector<SO3> rotations;
  for (const auto& xi : twists()) rotations.push_back(SO3::exp(xi.tail<3>()));
  size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(rotations[i++ % kCount].log());
}

void eigen_quaternion_to_angle_axis(benchmark::State& state) {
  std::vector<Eigen::Quaterniond> rotations;
  for (const auto& xi : twists()) rotations.push_back(SO3::exp(xi.tail<3>()).quaternion());
  size_t i = 0;
  for (auto _ : state) {
    const Eigen::AngleAxisd angle_axis(rotations[i++ % kCount]);
    benchmark::DoNotOptimize(Eigen::Vector3d(angle_axis.angle() * angle_axis.axis()));
  }
}

void hanzo_se3_exp(benchmark::State& state) {
  size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(SE3::exp(twists()[i++ % kCount]));
}

void eigen_matrix_exponential_4x4(benchmark::State& state) {
  size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(Eigen::Matrix4d(twist_matrix(twists()[i++ % kCount]).exp()));
}

void hanzo_se3_log(benchmark::State& state) {
  std::vector<SE3> poses;
  for (const auto& xi : twists()) poses.push_back(SE3::exp(xi));
  size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(poses[i++ % kCount].log());
}

void eigen_matrix_logarithm_4x4(benchmark::State& state) {
  std::vector<Eigen::Matrix4d> poses;
  for (const auto& xi : twists()) poses.push_back(SE3::exp(xi).matrix());
  size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(Eigen::Matrix4d(poses[i++ % kCount].log()));
}

void hanzo_se3_compose_and_act(benchmark::State& state) {
  std::vector<SE3> poses;
  for (const auto& xi : twists()) poses.push_back(SE3::exp(xi));
  const Eigen::Vector3d point(1.0, 2.0, 3.0);
  size_t i = 0;
  for (auto _ : state) {
    const SE3& a = poses[i % kCount];
    const SE3& b = poses[(i + 1) % kCount];
    ++i;
    benchmark::DoNotOptimize((a * b) * point);
  }
}

void eigen_isometry_compose_and_act(benchmark::State& state) {
  std::vector<Eigen::Isometry3d> poses;
  for (const auto& xi : twists()) poses.emplace_back(SE3::exp(xi).matrix());
  const Eigen::Vector3d point(1.0, 2.0, 3.0);
  size_t i = 0;
  for (auto _ : state) {
    const Eigen::Isometry3d& a = poses[i % kCount];
    const Eigen::Isometry3d& b = poses[(i + 1) % kCount];
    ++i;
    benchmark::DoNotOptimize((a * b) * point);
  }
}

void hanzo_se3_right_jacobian(benchmark::State& state) {
  size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(SE3::right_jacobian(twists()[i++ % kCount]));
}

constexpr GeodeticPoint kDatum{47.378177, 8.540192, 408.0};

std::vector<GeodeticPoint> nearby_points() {
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> uniform(-0.05, 0.05);
  std::vector<GeodeticPoint> points(kCount);
  for (auto& p : points) p = {kDatum.latitude_deg + uniform(rng), kDatum.longitude_deg + uniform(rng), kDatum.altitude_m + 100 * uniform(rng)};
  return points;
}

void hanzo_wgs84_to_enu(benchmark::State& state) {
  const EnuFrame frame = EnuFrame::create(kDatum).value();
  const std::vector<GeodeticPoint> points = nearby_points();
  size_t i = 0;
  for (auto _ : state) benchmark::DoNotOptimize(frame.to_enu(points[i++ % kCount]));
}

void geographiclib_local_cartesian_forward(benchmark::State& state) {
  const GeographicLib::LocalCartesian frame(kDatum.latitude_deg, kDatum.longitude_deg, kDatum.altitude_m);
  const std::vector<GeodeticPoint> points = nearby_points();
  size_t i = 0;
  for (auto _ : state) {
    const GeodeticPoint& p = points[i++ % kCount];
    double x, y, z;
    frame.Forward(p.latitude_deg, p.longitude_deg, p.altitude_m, x, y, z);
    benchmark::DoNotOptimize(x + y + z);
  }
}

BENCHMARK(hanzo_so3_exp);
BENCHMARK(eigen_angle_axis_to_quaternion);
BENCHMARK(hanzo_so3_log);
BENCHMARK(eigen_quaternion_to_angle_axis);
BENCHMARK(hanzo_se3_exp);
BENCHMARK(eigen_matrix_exponential_4x4);
BENCHMARK(hanzo_se3_log);
BENCHMARK(eigen_matrix_logarithm_4x4);
BENCHMARK(hanzo_se3_compose_and_act);
BENCHMARK(eigen_isometry_compose_and_act);
BENCHMARK(hanzo_se3_right_jacobian);
BENCHMARK(hanzo_wgs84_to_enu);
BENCHMARK(geographiclib_local_cartesian_forward);

}  // namespace

BENCHMARK_MAIN();
