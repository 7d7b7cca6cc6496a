// Pose-graph factors (Jacobians against numerical differentiation), g2o files (round trip,
// rejected input) and batch optimization to the published global optima of SE-Sync's
// benchmarks (../shared/data/pose_graph/SOURCE.md).

#include <cmath>
#include <filesystem>
#include <random>
#include <thread>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/chordal_initialization.hpp"
#include "hanzo/fusion/graph/g2o_io.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"

namespace hanzo::fusion::graph {
namespace {

using ::testing::HasSubstr;

template <typename Pose>
Pose perturbed(const Pose& pose, const typename Pose::Tangent& delta) {
  return pose * Pose::exp(delta);
}

// Central differences of the whitened residual in each variable's tangent space.
template <typename Pose>
void expect_jacobians_match(const Factor& factor, const Values& values) {
  std::vector<Eigen::MatrixXd> analytic;
  ASSERT_TRUE(factor.evaluate(values, &analytic).ok());
  constexpr double h = 1e-6;
  for (size_t v = 0; v < factor.keys().size(); ++v) {
    const Pose pose = values.at<Pose>(factor.keys()[v]).value();
    for (int k = 0; k < analytic[v].cols(); ++k) {
      typename Pose::Tangent delta = Pose::Tangent::Zero();
      delta(k) = h;
      Values plus = values, minus = values;
      plus.insert(factor.keys()[v], perturbed(pose, delta));
      minus.insert(factor.keys()[v], perturbed(pose, typename Pose::Tangent(-delta)));
      const Eigen::VectorXd numeric = (factor.evaluate(plus, nullptr).value() - factor.evaluate(minus, nullptr).value()) / (2 * h);
      EXPECT_LT((analytic[v].col(k) - numeric).cwiseAbs().maxCoeff(), 1e-6) << "variable " << v << " column " << k;
    }
  }
}

TEST(PoseFactors, JacobiansMatchNumericalDifferentiation) {
  std::mt19937 rng(4);
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::MatrixXd A3 = Eigen::MatrixXd::Random(3, 3), A6 = Eigen::MatrixXd::Random(6, 6);
  const GaussianNoise noise3 = GaussianNoise::from_information(A3 * A3.transpose() + Eigen::MatrixXd::Identity(3, 3)).value();
  const GaussianNoise noise6 = GaussianNoise::from_information(A6 * A6.transpose() + Eigen::MatrixXd::Identity(6, 6)).value();
  for (int trial = 0; trial < 10; ++trial) {
    const auto se2 = [&] { return SE2(2.0 * n(rng), Eigen::Vector2d(n(rng), n(rng))); };
    const auto se3 = [&] {
      SE3::Tangent xi;
      for (int i = 0; i < 6; ++i) xi(i) = n(rng);
      return SE3::exp(xi);
    };
    Values values;
    values.insert(X(0), se2());
    values.insert(X(1), se2());
    values.insert(X(2), se3());
    values.insert(X(3), se3());
    expect_jacobians_match<SE2>(BetweenFactorSE2(X(0), X(1), se2(), noise3), values);
    expect_jacobians_match<SE2>(PriorFactorSE2(X(0), se2(), noise3), values);
    expect_jacobians_match<SE3>(BetweenFactorSE3(X(2), X(3), se3(), noise6), values);
    expect_jacobians_match<SE3>(PriorFactorSE3(X(3), se3(), noise6), values);
    expect_jacobians_match<SE2>(ChordalBetweenFactor<SE2>(X(0), X(1), se2(), 2.0, 3.0), values);
    expect_jacobians_match<SE3>(ChordalBetweenFactor<SE3>(X(2), X(3), se3(), 2.0, 3.0), values);
  }
}

const std::string kData = std::string(HANZO_DATA_DIR) + "/pose_graph/se_sync/";

struct Optimized {
  double initial_objective = 0.0;
  double final_objective = 0.0;
  double final_g2o_chi2 = 0.0;
  OptimizationSummary summary;
};

Optimized optimize_file(const std::string& file, PoseGraph::Objective objective, bool chordal_start = false) {
  const PoseGraph graph = read_g2o(kData + file).value();
  Values values = chordal_start ? chordal_initialization(graph).value() : graph.initial;
  Optimized result;
  result.initial_objective = se_sync_objective(graph, values).value();
  BatchOptimizerConfig config;
  config.fixed = graph.fixed;
  result.summary = optimize(graph.factor_graph(objective).value(), values, config).value();
  result.final_objective = se_sync_objective(graph, values).value();
  result.final_g2o_chi2 = g2o_chi2(graph, values).value();
  std::printf("%s: SE-Sync objective %.6g -> %.6g, g2o chi2 %.6g, %d iterations, %.3f s\n", file.c_str(), result.initial_objective,
              result.final_objective, result.final_g2o_chi2, result.summary.iterations, result.summary.seconds);
  return result;
}

// SE-Sync's published global optima: intel f* = 52.3482 (notebook), garage 1.263 (table).
TEST(BatchOptimizer, ReachesThePublishedOptimumOfIntel) {
  const Optimized intel = optimize_file("intel.g2o", PoseGraph::Objective::kChordal);
  EXPECT_NEAR(intel.final_objective, 52.3482, 1e-3 * 52.3482);
  EXPECT_TRUE(intel.summary.converged);
  // The geodesic (g2o) objective has its own optimum; its SE-Sync cost is a little higher.
  const Optimized geodesic = optimize_file("intel.g2o", PoseGraph::Objective::kGeodesic);
  EXPECT_GT(geodesic.final_objective, intel.final_objective);
  EXPECT_LT(geodesic.final_g2o_chi2, intel.final_g2o_chi2);
}

TEST(BatchOptimizer, ReachesThePublishedOptimumOfManhattanFromChainedOdometry) {
  // manhattan.g2o has no VERTEX lines: the start is the chained odometry.
  const Optimized manhattan = optimize_file("manhattan.g2o", PoseGraph::Objective::kChordal);
  EXPECT_NEAR(manhattan.final_objective, 6431.42, 1e-3 * 6431.42);  // SE-Sync f* = 6.432e3
}

TEST(BatchOptimizer, ReachesThePublishedOptimumOfParkingGarage) {
  const Optimized garage = optimize_file("parking-garage.g2o", PoseGraph::Objective::kChordal);
  // SE-Sync's table gives f* = 1.263 (four digits); we reach 1.262528 (the same value from an
  // independent numpy evaluation of SE-Sync's cost at our poses), which rounds to it. The
  // 1.26391 of SOURCE.md's scipy reproduction rounds to 1.264: that run stopped short.
  EXPECT_NEAR(garage.final_objective, 1.263, 1e-3 * 1.263);
  EXPECT_GE(garage.final_objective, 1.2625);  // a global optimum cannot be beaten
}

// Batch optimizations running on several threads at once (a server optimizes many sessions'
// graphs) give each the same optimum as alone: the sparse Cholesky's BLAS must be thread-safe
// (OpenBLAS built without locking is not: concurrent factorizations corrupted each other).
TEST(BatchOptimizer, ConcurrentOptimizationsReachTheSameOptimumAsOne) {
  const PoseGraph graph = read_g2o(kData + "parking-garage.g2o").value();
  const FactorGraph factors = graph.factor_graph(PoseGraph::Objective::kChordal).value();
  BatchOptimizerConfig config;
  config.fixed = graph.fixed;
  const auto solve = [&] {
    Values values = graph.initial;
    EXPECT_TRUE(optimize(factors, values, config).ok());
    return se_sync_objective(graph, values).value();
  };
  const double alone = solve();
  std::vector<double> concurrent(3, 0.0);
  std::vector<std::thread> threads;
  for (std::size_t i = 0; i < concurrent.size(); ++i) threads.emplace_back([&, i] { concurrent[i] = solve(); });
  for (std::thread& thread : threads) thread.join();
  for (const double objective : concurrent) EXPECT_NEAR(objective, alone, 1e-9 * alone);

  // A bad setting is refused by name; the values stay as they were.
  Values values = graph.initial;
  BatchOptimizerConfig bad = config;
  bad.initial_trust_region_radius = 0.0;
  auto refused = optimize(factors, values, bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.error().message.find("initial_trust_region_radius"), std::string::npos);
  EXPECT_DOUBLE_EQ(se_sync_objective(graph, values).value(), se_sync_objective(graph, graph.initial).value());
}

// city10000 started from its own VERTEX guess stops in a local minimum (GTSAM's LM too, at
// over 30000x the optimum): from the chordal initialization it reaches SE-Sync's f* = 638.6.
TEST(ChordalInitialization, City10000ReachesThePublishedOptimum) {
  const Optimized city = optimize_file("city10000.g2o", PoseGraph::Objective::kChordal, true);
  EXPECT_NEAR(city.final_objective, 638.6, 1e-3 * 638.6);
  EXPECT_LT(city.initial_objective, 1.2 * 638.6);  // the initialization alone is already close
}

// Exact measurements (a chain and loop closures between random poses): the chordal
// initialization recovers every pose exactly from nothing, in 2D and 3D; a vertex connected to
// no anchor is refused.
TEST(ChordalInitialization, RecoversExactPosesAndRefusesDisconnectedGraphs) {
  std::mt19937 rng(8);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int dimension : {2, 3}) {
    PoseGraph graph;
    graph.dimension = dimension;
    std::vector<Value> truth;
    for (int i = 0; i < 40; ++i) {
      SE3::Tangent xi;
      for (int k = 0; k < 6; ++k) xi(k) = (k < 3 ? 5.0 : 1.5) * n(rng);
      truth.push_back(dimension == 3 ? Value(SE3::exp(xi)) : Value(SE2(xi(5), Eigen::Vector2d(xi(0), xi(1)))));
      graph.vertices.push_back(X(i));
    }
    graph.initial.insert(X(0), truth[0]);
    graph.fixed = {X(0)};
    const auto relative = [&](int i, int j) -> Value {
      if (dimension == 3) return std::get<SE3>(truth[i]).inverse() * std::get<SE3>(truth[j]);
      return std::get<SE2>(truth[i]).inverse() * std::get<SE2>(truth[j]);
    };
    const Eigen::MatrixXd information = Eigen::MatrixXd::Identity(3 * (dimension - 1), 3 * (dimension - 1));
    for (int i = 0; i + 1 < 40; ++i) graph.edges.push_back({X(i), X(i + 1), relative(i, i + 1), information, information});
    for (int i = 0; i < 30; i += 3) graph.edges.push_back({X(i), X(i + 7), relative(i, i + 7), information, information});
    const Values values = chordal_initialization(graph).value();
    for (int i = 0; i < 40; ++i) {
      if (dimension == 3) {
        const SE3 error = std::get<SE3>(truth[i]).inverse() * values.at<SE3>(X(i)).value();
        EXPECT_LT(error.log().norm(), 1e-9) << i;
      } else {
        const SE2 error = std::get<SE2>(truth[i]).inverse() * values.at<SE2>(X(i)).value();
        EXPECT_LT(error.log().norm(), 1e-9) << i;
      }
    }
    graph.vertices.push_back(X(99));  // no edge reaches it
    EXPECT_THAT(chordal_initialization(graph).error().message, HasSubstr("connected to an anchor"));
    graph.edges.push_back({X(99), X(98), relative(0, 1), information, information});
    EXPECT_THAT(chordal_initialization(graph).error().message, HasSubstr("x98 is not a vertex"));
  }
}

// Ten false loop closures (identity between vertices far apart, as confident as the real
// edges): without a robust kernel they bend the map by metres; DCS switches them off, Cauchy
// nearly.
TEST(RobustKernels, SwitchOffFalseLoopClosures) {
  const PoseGraph graph = read_g2o(kData + "intel.g2o").value();
  BatchOptimizerConfig config;
  config.fixed = graph.fixed;
  Values clean = graph.initial;
  ASSERT_TRUE(optimize(graph.factor_graph().value(), clean, config).ok());

  const auto with_outliers = [&](RobustKernel kernel) {
    FactorGraph factors = graph.factor_graph().value();
    const GaussianNoise noise = GaussianNoise::from_information(graph.edges.front().information).value();
    for (uint64_t k = 0; k < 10; ++k) {
      factors.emplace_robust<BetweenFactorSE2>(kernel, X(100 + 137 * k), X(900 + 61 * k), SE2(), noise);
    }
    Values values = graph.initial;
    EXPECT_TRUE(optimize(factors, values, config).ok());
    double worst = 0.0;
    for (Key key : graph.vertices) {
      worst = std::max(worst, (values.at<SE2>(key).value().translation() - clean.at<SE2>(key).value().translation()).norm());
    }
    return worst;
  };
  const double plain = with_outliers({});
  const double dcs = with_outliers({RobustKernel::Type::kDcs, 1.0});
  const double cauchy = with_outliers({RobustKernel::Type::kCauchy, 1.0});
  std::printf("10 false loop closures on intel: largest pose shift %.3f m plain, %.4f m DCS, %.4f m Cauchy\n", plain, dcs, cauchy);
  EXPECT_GT(plain, 1.0);
  EXPECT_LT(dcs, 0.05);
  EXPECT_LT(cauchy, 0.05 * plain);  // Cauchy keeps a little influence (0.3 m of 26 m)
}

TEST(RobustKernels, CostsFollowTheirDefinitions) {
  BetweenFactorSE2 factor(X(0), X(1), SE2(), GaussianNoise::from_sigmas(Eigen::Vector3d::Ones()).value());
  EXPECT_EQ(factor.robust_cost(9.0), 9.0);
  factor.set_robust_kernel({RobustKernel::Type::kHuber, 1.0});
  EXPECT_DOUBLE_EQ(factor.robust_cost(0.25), 0.25);
  EXPECT_DOUBLE_EQ(factor.robust_cost(9.0), 2.0 * 3.0 - 1.0);
  factor.set_robust_kernel({RobustKernel::Type::kCauchy, 2.0});
  EXPECT_DOUBLE_EQ(factor.robust_cost(4.0), 4.0 * std::log(2.0));
  factor.set_robust_kernel({RobustKernel::Type::kDcs, 1.0});
  EXPECT_DOUBLE_EQ(factor.robust_cost(0.5), 0.5);
  EXPECT_DOUBLE_EQ(factor.robust_cost(9.0), (2.0 / 10.0) * (2.0 / 10.0) * 9.0);
}

// A prior on X0 (sigma 0.1) and one odometry edge to X1 (sigma 0.2) along the identity: X1's
// marginal covariance is 0.1^2 + 0.2^2 per axis; rotated edges move it by the adjoint.
TEST(MarginalCovariances, ChainAddsTheEdgeCovariance) {
  FactorGraph graph;
  graph.emplace<PriorFactorSE3>(X(0), SE3(), GaussianNoise::from_sigmas(Eigen::VectorXd::Constant(6, 0.1)).value());
  graph.emplace<BetweenFactorSE3>(X(0), X(1), SE3(), GaussianNoise::from_sigmas(Eigen::VectorXd::Constant(6, 0.2)).value());
  const SE3 turn(SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), 0.5), Eigen::Vector3d(1.0, 0.0, 0.0));
  graph.emplace<BetweenFactorSE3>(X(1), X(2), turn, GaussianNoise::from_sigmas(Eigen::VectorXd::Constant(6, 0.2)).value());
  Values values;
  values.insert(X(0), SE3());
  values.insert(X(1), SE3());
  values.insert(X(2), turn);
  const std::vector<Eigen::MatrixXd> covariances = marginal_covariances(graph, values, {X(0), X(1), X(2)}).value();
  EXPECT_LT((covariances[0] - 0.01 * Eigen::MatrixXd::Identity(6, 6)).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((covariances[1] - 0.05 * Eigen::MatrixXd::Identity(6, 6)).cwiseAbs().maxCoeff(), 1e-9);
  const SE3::Jacobian Ad = turn.inverse().adjoint();
  const Eigen::MatrixXd expected = Ad * (0.05 * Eigen::MatrixXd::Identity(6, 6)) * Ad.transpose() + 0.04 * Eigen::MatrixXd::Identity(6, 6);
  EXPECT_LT((covariances[2] - expected).cwiseAbs().maxCoeff(), 1e-9);

  // Without the prior nothing fixes the gauge: refused with a reason.
  FactorGraph unanchored;
  unanchored.emplace<BetweenFactorSE3>(X(0), X(1), SE3(), GaussianNoise::from_sigmas(Eigen::VectorXd::Constant(6, 0.2)).value());
  const auto refused = marginal_covariances(unanchored, values, {X(1)});
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused.error().message, HasSubstr("rank deficient"));
}

TEST(G2o, WriteReadRoundTripIsExact) {
  const PoseGraph graph = read_g2o(kData + "tinyGrid3D.g2o").value();
  const std::filesystem::path path = std::filesystem::temp_directory_path() / ("hanzo_g2o_" + std::to_string(::getpid()) + ".g2o");
  ASSERT_TRUE(write_g2o(path.string(), graph, graph.initial).ok());
  const PoseGraph back = read_g2o(path.string()).value();
  ASSERT_EQ(back.edges.size(), graph.edges.size());
  EXPECT_NEAR(g2o_chi2(back, back.initial).value(), g2o_chi2(graph, graph.initial).value(), 1e-9);
  for (Key key : graph.vertices) {
    EXPECT_EQ(back.initial.at<SE3>(key).value().translation(), graph.initial.at<SE3>(key).value().translation());
  }
  std::filesystem::remove(path);
}

// A pose as a homogeneous matrix (3x3 in 2D, 4x4 in 3D).
Eigen::MatrixXd matrix_of(const Value& pose) {
  if (const auto* se3 = std::get_if<SE3>(&pose)) return se3->matrix();
  const SE2& se2 = std::get<SE2>(pose);
  Eigen::Matrix3d matrix = Eigen::Matrix3d::Identity();
  matrix.topLeftCorner<2, 2>() = se2.rotation_matrix();
  matrix.block<2, 1>(0, 2) = se2.translation();
  return matrix;
}

// TORO files (GTSAM's examples): w100.graph as GTSAM's testDataset reads it (100 poses, 300
// edges, its 40 EQUIV lines skipped, the first edge 1 -> 0), a write/read round trip in both
// dimensions, and sphere2500 in TORO's EDGE3 format optimized close to its noise-free poses.
TEST(Toro, ReadsGtsamsFilesAndRoundTrips) {
  const std::string gtsam = std::string(HANZO_DATA_DIR) + "/pose_graph/gtsam/";
  const PoseGraph w100 = read_g2o(gtsam + "w100.graph").value();
  EXPECT_EQ(w100.dimension, 2);
  EXPECT_EQ(w100.vertices.size(), 100u);
  EXPECT_EQ(w100.edges.size(), 300u);
  EXPECT_EQ(w100.skipped_equivalences, 40);
  EXPECT_EQ(w100.edges[0].from, X(1));
  EXPECT_EQ(w100.edges[0].to, X(0));
  const SE2 first = std::get<SE2>(w100.edges[0].measurement);
  EXPECT_NEAR(first.translation().x(), -0.99879, 1e-12);
  EXPECT_NEAR(first.translation().y(), 0.0417574, 1e-12);
  EXPECT_NEAR(first.angle(), -0.00818381, 1e-12);

  const PoseGraph sphere = read_g2o(gtsam + "sphere2500.txt").value();
  EXPECT_EQ(sphere.dimension, 3);
  EXPECT_EQ(sphere.edges.size(), 4949u);
  for (const PoseGraph* graph : {&w100, &sphere}) {
    const std::filesystem::path path = std::filesystem::temp_directory_path() / ("hanzo_toro_" + std::to_string(::getpid()) + ".graph");
    ASSERT_TRUE(write_toro(path.string(), *graph, graph->initial).ok());
    const PoseGraph back = read_g2o(path.string()).value();
    std::filesystem::remove(path);
    ASSERT_EQ(back.edges.size(), graph->edges.size());
    for (size_t e = 0; e < graph->edges.size(); ++e) {
      EXPECT_LT((back.edges[e].information - graph->edges[e].information).cwiseAbs().maxCoeff(), 1e-9);
      EXPECT_LT((matrix_of(back.edges[e].measurement) - matrix_of(graph->edges[e].measurement)).cwiseAbs().maxCoeff(), 1e-12);
    }
    EXPECT_NEAR(g2o_chi2(back, back.initial).value(), g2o_chi2(*graph, graph->initial).value(), 1e-6 * g2o_chi2(*graph, graph->initial).value());
  }

  // Noise-free poses: chain the i -> i+1 edges of the ground-truth file.
  const PoseGraph truth = read_g2o(gtsam + "sphere2500_groundtruth.txt").value();
  Values optimized = chordal_initialization(sphere).value();
  BatchOptimizerConfig config;
  config.fixed = sphere.fixed;
  ASSERT_TRUE(optimize(sphere.factor_graph().value(), optimized, config).ok());
  double squared = 0.0, squared_start = 0.0;
  for (int i = 0; i < 2500; ++i) {
    const Eigen::Vector3d truth_position = truth.initial.at<SE3>(X(i)).value().translation();
    squared += (optimized.at<SE3>(X(i)).value().translation() - truth_position).squaredNorm();
    squared_start += (sphere.initial.at<SE3>(X(i)).value().translation() - truth_position).squaredNorm();
  }
  const double rmse = std::sqrt(squared / 2500), rmse_start = std::sqrt(squared_start / 2500);
  std::printf("sphere2500 (TORO): position RMSE to the noise-free poses %.3f m (odometry %.3f m)\n", rmse, rmse_start);
  EXPECT_LT(rmse, 0.1 * rmse_start);
}

// Real benchmark files carry information matrices that are only semi-definite (a planar
// robot's graph in 3D: no z information) or slightly indefinite from rounding. They load, with
// a warning naming file and line, and optimize to what the well-posed version of the graph gives.
TEST(G2o, RepairsInformationThatIsNotPositiveDefiniteAndWarnsWithTheLine) {
  // A square loop in the plane with noisy odometry, written as 3D edges.
  const auto square = [](const std::string& information) {
    std::string text;
    const double noise[4][3] = {{0.05, -0.02, 0.01}, {-0.03, 0.04, -0.02}, {0.02, 0.01, 0.015}, {-0.04, -0.03, 0.0}};
    for (int i = 0; i < 4; ++i) {
      const double yaw = M_PI / 2 + noise[i][2];
      text += fmt::format("EDGE_SE3:QUAT {} {} {} {} 0 0 0 {} {} {}\n", i, (i + 1) % 4, 2.0 + noise[i][0], noise[i][1], std::sin(yaw / 2),
                          std::cos(yaw / 2), information);
    }
    return "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\n" + text;
  };
  // Upper triangles, order x y z | qx qy qz.
  const std::string well_posed = "100 0 0 0 0 0 100 0 0 0 0 100 0 0 0 400 0 0 400 0 400";
  const std::string no_z = "100 0 0 0 0 0 100 0 0 0 0 0 0 0 0 400 0 0 400 0 400";
  const auto solve = [](const PoseGraph& graph) {
    Values values = graph.initial;
    BatchOptimizerConfig config;
    config.fixed = graph.fixed;
    EXPECT_TRUE(optimize(graph.factor_graph().value(), values, config).ok());
    return values;
  };
  const PoseGraph reference = parse_g2o(square(well_posed), "square.g2o").value();
  EXPECT_TRUE(reference.warnings.empty());
  const Result<PoseGraph> planar = parse_g2o(square(no_z), "planar.g2o");
  ASSERT_TRUE(planar.ok()) << planar.error().message;
  // Two warnings per edge: repaired for the geodesic factors, and SE-Sync's weights from the
  // repaired matrix (the translation block itself has no z information).
  ASSERT_EQ(planar->warnings.size(), 8u);
  EXPECT_THAT(planar->warnings[0].text, HasSubstr("planar.g2o:2: EDGE_SE3:QUAT: the information matrix is not positive definite"));
  EXPECT_EQ(planar->warnings[1].kind, "se_sync_weights_from_repaired");
  EXPECT_THAT(planar->warnings[6].text, HasSubstr("planar.g2o:5: "));
  const std::vector<WarningGroup> groups = group_warnings(planar->warnings);
  ASSERT_EQ(groups.size(), 2u);
  EXPECT_EQ(groups[0].count, 4u);
  EXPECT_EQ(groups[1].count, 4u);
  const Values expected = solve(reference), repaired = solve(*planar);
  for (int i = 0; i < 4; ++i) {
    const SE3 a = expected.at<SE3>(X(i)).value(), b = repaired.at<SE3>(X(i)).value();
    EXPECT_LT((a.translation() - b.translation()).norm(), 1e-6) << i;
    EXPECT_LT((a.rotation().inverse() * b.rotation()).log().norm(), 1e-6) << i;
  }

  // Slightly indefinite (rounding) and negative 2D information: repaired, named, never refused.
  const std::string vertices = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n";
  const Result<PoseGraph> rounded = parse_g2o(vertices + "EDGE_SE2 0 1 1 0 0 1 1.0000001 0 1 0 1\nEDGE_SE2 0 1 1 0 0 -1 0 0 1 0 1\n", "rounded.g2o");
  ASSERT_TRUE(rounded.ok()) << rounded.error().message;
  ASSERT_EQ(rounded->warnings.size(), 4u);
  EXPECT_THAT(rounded->warnings[0].text, HasSubstr("rounded.g2o:3: EDGE_SE2:"));
  EXPECT_THAT(rounded->warnings[2].text, HasSubstr("rounded.g2o:4: EDGE_SE2:"));
  for (const PoseGraphEdge& edge : rounded->edges) EXPECT_TRUE(GaussianNoise::from_information(edge.information).ok());
}

TEST(G2o, RejectsBadInputNamingTheLine) {
  const auto error_of = [](const std::string& text) {
    const Result<PoseGraph> graph = parse_g2o(text, "bad.g2o");
    return graph ? std::string("ok") : graph.error().message;
  };
  const std::string vertices = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n";
  EXPECT_EQ(error_of(vertices + "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"), "ok");
  EXPECT_EQ(error_of(vertices + "EDGE_SE2 0 1 1 0 0 1 0 0 1 0\n"), "bad.g2o:3: EDGE_SE2: expected 11 numbers, got 10");
  EXPECT_EQ(error_of(vertices + "EDGE_SE2 0 1 nan 0 0 1 0 0 1 0 1\n"), "bad.g2o:3: EDGE_SE2: non-finite value nan");
  EXPECT_EQ(error_of(vertices + "EDGE_SE4 0 1\n"),
            "bad.g2o:3: EDGE_SE4: unknown tag (expected VERTEX_SE2, EDGE_SE2, VERTEX_SE3:QUAT, EDGE_SE3:QUAT, FIX, or TORO's VERTEX2, EDGE2, VERTEX3, EDGE3, EQUIV)");
  EXPECT_THAT(error_of("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 2\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"), HasSubstr("quaternion norm 2 is not 1"));
  EXPECT_EQ(error_of(vertices + "VERTEX_SE2 7 0 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 5 6 1 0 0 1 0 0 1 0 1\n"),
            "bad.g2o: vertex 5 is not connected to the rest of the graph");
  EXPECT_EQ(error_of(vertices), "bad.g2o: no edges");
}

}  // namespace
}  // namespace hanzo::fusion::graph
