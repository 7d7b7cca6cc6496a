// Marginalization: the prior's Jacobians against numerical differentiation; on a linear graph the
// marginalized graph has exactly the full graph's optimum and covariances of what remains; on a
// nonlinear pose graph the same at the point it was linearized; a sliding window of the
// IncrementalSmoother stays bounded and ends near the full graph's optimum.

#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "graph/jacobian_check.hpp"
#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/incremental_smoother.hpp"
#include "hanzo/fusion/graph/marginalization.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"

namespace hanzo::fusion::graph {
namespace {

using ::testing::HasSubstr;

// Linear factors on points: x_j - x_i = z (or x = z for a prior), sigma per axis.
class PointFactor final : public Factor {
 public:
  PointFactor(std::vector<Key> keys, Eigen::Vector3d measured, double sigma) : Factor(std::move(keys)), measured_(measured), sigma_(sigma) {}
  int dimension() const override { return 3; }
  Result<Eigen::VectorXd> evaluate(const Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override {
    Eigen::Vector3d last;
    HANZO_ASSIGN_OR_RETURN(last, values.at<Eigen::Vector3d>(keys().back()));
    Eigen::Vector3d first = Eigen::Vector3d::Zero();
    if (keys().size() == 2) HANZO_ASSIGN_OR_RETURN(first, values.at<Eigen::Vector3d>(keys().front()));
    if (jacobians) {
      jacobians->clear();
      if (keys().size() == 2) jacobians->push_back(-Eigen::Matrix3d::Identity() / sigma_);
      jacobians->push_back(Eigen::Matrix3d::Identity() / sigma_);
    }
    return Eigen::VectorXd((last - first - measured_) / sigma_);
  }

 private:
  Eigen::Vector3d measured_;
  double sigma_;
};

TEST(Marginalization, PriorJacobiansMatchNumericalDifferentiation) {
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0.0, 1.0);
  const std::vector<Key> keys = {X(0), V(0), B(0), symbol('p', 0)};
  const std::vector<Value> point = {SE3(SO3::exp({0.3, -0.2, 1.0}), Eigen::Vector3d(1, 2, 3)), Eigen::Vector3d(0.5, 0, 0), ImuBias{},
                                    SE2(0.4, Eigen::Vector2d(2, -1))};
  Eigen::MatrixXd J0(10, 18);
  for (Eigen::Index i = 0; i < J0.size(); ++i) J0.data()[i] = n(rng);
  Eigen::VectorXd r0(10);
  for (Eigen::Index i = 0; i < r0.size(); ++i) r0(i) = n(rng);
  const LinearizedPriorFactor prior(keys, point, J0, r0);
  Values values;
  values.insert(X(0), std::get<SE3>(point[0]) * SE3::exp((SE3::Tangent() << 0.2, -0.1, 0.3, 0.1, 0.2, -0.3).finished()));
  values.insert(V(0), Eigen::Vector3d(0.7, -0.1, 0.2));
  values.insert(B(0), ImuBias{{0.01, 0.02, -0.03}, {0.001, 0.0, 0.002}});
  values.insert(symbol('p', 0), std::get<SE2>(point[3]) * SE2::exp({0.1, 0.2, -0.3}));
  expect_jacobians_match(prior, values);
  // At the linearization point the residual is r0.
  Values at_point;
  for (std::size_t i = 0; i < keys.size(); ++i) at_point.insert(keys[i], point[i]);
  EXPECT_LT((prior.evaluate(at_point, nullptr).value() - r0).norm(), 1e-12);
}

// Converged to the last digits (the default tolerance stops at a 1e-6 relative cost change).
BatchOptimizerConfig tight() {
  BatchOptimizerConfig config;
  config.function_tolerance = 1e-15;
  config.gradient_tolerance = 1e-15;
  config.parameter_tolerance = 1e-15;
  return config;
}

// Points p0..p5: a prior on p0, noisy differences along the chain and two across it.
FactorGraph point_graph() {
  std::mt19937 rng(9);
  std::normal_distribution<double> n(0.0, 0.1);
  auto noisy = [&](const Eigen::Vector3d& v) { return Eigen::Vector3d(v + Eigen::Vector3d(n(rng), n(rng), n(rng))); };
  FactorGraph graph;
  graph.add(std::make_shared<PointFactor>(std::vector<Key>{L(0)}, Eigen::Vector3d(0, 0, 0), 0.05));
  for (int i = 1; i < 6; ++i) graph.add(std::make_shared<PointFactor>(std::vector<Key>{L(i - 1), L(i)}, noisy({1.0, 0.5, 0.0}), 0.1 * i));
  graph.add(std::make_shared<PointFactor>(std::vector<Key>{L(1), L(4)}, noisy({3.0, 1.5, 0.0}), 0.2));
  graph.add(std::make_shared<PointFactor>(std::vector<Key>{L(0), L(3)}, noisy({3.0, 1.5, 0.0}), 0.3));
  return graph;
}

// The factors of `graph` that touch none of `keys`, and those that do.
std::pair<FactorGraph, std::vector<FactorPointer>> split(const FactorGraph& graph, const std::set<Key>& keys) {
  std::pair<FactorGraph, std::vector<FactorPointer>> out;
  for (const FactorPointer& factor : graph.factors()) {
    const bool touches = std::any_of(factor->keys().begin(), factor->keys().end(), [&](Key key) { return keys.count(key) != 0; });
    if (touches) {
      out.second.push_back(factor);
    } else {
      out.first.add(factor);
    }
  }
  return out;
}

TEST(Marginalization, OnALinearGraphKeepsTheOptimumAndCovariancesOfWhatRemains) {
  const FactorGraph graph = point_graph();
  Values full;
  for (int i = 0; i < 6; ++i) full.insert(L(i), Eigen::Vector3d(0.3 * i, -0.2, 1.0));  // anywhere: linear
  const Values start = full;
  ASSERT_TRUE(optimize(graph, full, tight()).ok());
  // Marginalized at the (not optimal) start: exact all the same for a linear graph.
  const std::set<Key> marginalized = {L(0), L(1)};
  auto [reduced, removed] = split(graph, marginalized);
  const Result<Marginalization> marginal = marginalize(removed, start, marginalized);
  ASSERT_TRUE(marginal.ok()) << marginal.error().message;
  ASSERT_TRUE(marginal->prior);
  EXPECT_EQ(marginal->kept, (std::vector<Key>{L(2), L(3), L(4)}));
  reduced.add(marginal->prior);
  Values remaining;
  for (int i = 2; i < 6; ++i) remaining.insert(L(i), start.at<Eigen::Vector3d>(L(i)).value());
  ASSERT_TRUE(optimize(reduced, remaining, tight()).ok());
  for (int i = 2; i < 6; ++i) EXPECT_LT((remaining.at<Eigen::Vector3d>(L(i)).value() - full.at<Eigen::Vector3d>(L(i)).value()).norm(), 1e-8) << i;
  const auto full_covariance = marginal_covariances(graph, full, {L(5), L(2)}).value();
  const auto reduced_covariance = marginal_covariances(reduced, remaining, {L(5), L(2)}).value();
  for (int k = 0; k < 2; ++k) EXPECT_LT((full_covariance[k] - reduced_covariance[k]).norm(), 1e-9 * full_covariance[k].norm()) << k;
}

TEST(Marginalization, OnAPoseGraphKeepsTheOptimumItWasLinearizedAt) {
  std::mt19937 rng(4);
  std::normal_distribution<double> n(0.0, 1.0);
  const GaussianNoise odometry = GaussianNoise::from_sigmas((Eigen::VectorXd(6) << 0.05, 0.05, 0.05, 0.01, 0.01, 0.01).finished()).value();
  FactorGraph graph;
  Values values;
  SE3 truth;
  graph.emplace<PriorFactorSE3>(X(0), truth, odometry);
  values.insert(X(0), truth);
  for (int i = 1; i < 8; ++i) {
    const SE3 step = SE3::exp((SE3::Tangent() << 1.0, 0.2, 0.0, 0.0, 0.0, 0.3).finished());
    SE3::Tangent noise;
    for (int k = 0; k < 6; ++k) noise(k) = (k < 3 ? 0.05 : 0.01) * n(rng);
    graph.emplace<BetweenFactorSE3>(X(i - 1), X(i), step * SE3::exp(noise), odometry);
    truth = truth * step;
    values.insert(X(i), truth);
  }
  graph.emplace<BetweenFactorSE3>(X(1), X(6), values.at<SE3>(X(1)).value().inverse() * values.at<SE3>(X(6)).value(), odometry);
  ASSERT_TRUE(optimize(graph, values, tight()).ok());
  const std::set<Key> marginalized = {X(0), X(1), X(2)};
  auto [reduced, removed] = split(graph, marginalized);
  const Result<Marginalization> marginal = marginalize(removed, values, marginalized);
  ASSERT_TRUE(marginal.ok()) << marginal.error().message;
  EXPECT_EQ(marginal->kept, (std::vector<Key>{X(3), X(6)}));
  reduced.add(marginal->prior);
  Values remaining;
  for (int i = 3; i < 8; ++i) remaining.insert(X(i), values.at<SE3>(X(i)).value() * SE3::exp(SE3::Tangent::Constant(0.01)));
  ASSERT_TRUE(optimize(reduced, remaining, tight()).ok());
  for (int i = 3; i < 8; ++i) {
    const SE3 error = values.at<SE3>(X(i)).value().inverse() * remaining.at<SE3>(X(i)).value();
    EXPECT_LT(error.log().norm(), 1e-6) << i;
  }
  const auto full_covariance = marginal_covariances(graph, values, {X(7)}).value();
  const auto reduced_covariance = marginal_covariances(reduced, remaining, {X(7)}).value();
  EXPECT_LT((full_covariance[0] - reduced_covariance[0]).norm(), 1e-4 * full_covariance[0].norm());
}

TEST(Marginalization, UnconstrainedDirectionsCarryNoInformation) {
  // Only a difference between two points: marginalizing one leaves nothing on the other.
  FactorGraph graph;
  graph.add(std::make_shared<PointFactor>(std::vector<Key>{L(0), L(1)}, Eigen::Vector3d(1, 0, 0), 0.1));
  Values values;
  values.insert(L(0), Eigen::Vector3d::Zero());
  values.insert(L(1), Eigen::Vector3d(1, 0, 0));
  const Result<Marginalization> marginal = marginalize(graph.factors(), values, {L(0)});
  ASSERT_TRUE(marginal.ok());
  EXPECT_FALSE(marginal->prior);
  EXPECT_FALSE(marginalize(graph.factors(), Values{}, {L(0)}).ok()) << "no values";
}

TEST(IncrementalSmoother, ASlidingWindowStaysBoundedAndEndsNearTheFullOptimum) {
  std::mt19937 rng(12);
  std::normal_distribution<double> n(0.0, 1.0);
  const GaussianNoise odometry = GaussianNoise::from_sigmas((Eigen::VectorXd(6) << 0.05, 0.05, 0.05, 0.005, 0.005, 0.005).finished()).value();
  const GaussianNoise fix = GaussianNoise::from_sigmas((Eigen::VectorXd(6) << 0.3, 0.3, 0.3, 1.0, 1.0, 1.0).finished()).value();
  IncrementalSmootherConfig config;
  config.background_batch = false;
  IncrementalSmoother window(config);
  FactorGraph full;
  Values full_values;
  constexpr int kPoses = 80, kWindow = 12;
  SE3 truth, odometry_pose;
  std::size_t largest_graph = 0;
  for (int i = 0; i < kPoses; ++i) {
    GraphUpdate update;
    const SE3 step = SE3::exp((SE3::Tangent() << 1.0, 0.0, 0.0, 0.0, 0.0, 0.05).finished());
    if (i > 0) {
      SE3::Tangent noise;
      for (int k = 0; k < 6; ++k) noise(k) = (k < 3 ? 0.05 : 0.005) * n(rng);
      const SE3 measured = step * SE3::exp(noise);
      truth = truth * step;
      odometry_pose = odometry_pose * measured;
      update.factors.emplace<BetweenFactorSE3>(X(i - 1), X(i), measured, odometry);
    }
    update.values.insert(X(i), odometry_pose);
    if (i % 4 == 0) {  // a position fix
      const SE3 fixed(truth.rotation(), truth.translation() + 0.3 * Eigen::Vector3d(n(rng), n(rng), n(rng)));
      update.factors.emplace<PriorFactorSE3>(X(i), fixed, fix);
    }
    for (const FactorPointer& factor : update.factors.factors()) full.add(factor);
    full_values.insert(X(i), odometry_pose);
    ASSERT_TRUE(window.update(update.factors, update.values).ok());
    if (i >= kWindow) {
      ASSERT_TRUE(window.marginalize({X(i - kWindow)}).ok());
    }
    largest_graph = std::max(largest_graph, window.graph().size());
  }
  EXPECT_LE(largest_graph, static_cast<std::size_t>(kWindow + kWindow / 4 + 2));
  EXPECT_EQ(window.estimate().size(), static_cast<std::size_t>(kWindow));
  ASSERT_TRUE(window.wait_for_batch().ok());
  ASSERT_TRUE(optimize(full, full_values).ok());
  const SE3 error = full_values.at<SE3>(X(kPoses - 1)).value().inverse() * window.estimate().at<SE3>(X(kPoses - 1)).value();
  EXPECT_LT(error.translation().norm(), 0.02);
  EXPECT_LT(error.rotation().log().norm(), 0.002);

  // Kept factors keep their variable: X(70)'s pose-graph copy stays with its fix, its window
  // factors (odometry) go into the prior.
  const std::size_t factors_before = window.graph().size();
  const Result<std::vector<Key>> split_pose =
      window.marginalize({X(kPoses - kWindow)}, [](const Factor& factor) { return dynamic_cast<const PriorFactorSE3*>(&factor) != nullptr; });
  ASSERT_TRUE(split_pose.ok()) << split_pose.error().message;
  EXPECT_TRUE(window.estimate().exists(X(kPoses - kWindow)));
  EXPECT_EQ(window.factors_of(X(kPoses - kWindow)).size(), 1U) << "its fix only";
  EXPECT_EQ(*split_pose, (std::vector<Key>{X(kPoses - kWindow + 1)}));
  EXPECT_LT(window.graph().size(), factors_before);

  // Refused, changing nothing: an unknown key, a fixed one.
  const Result<std::vector<Key>> unknown = window.marginalize({X(0)});
  ASSERT_FALSE(unknown.ok());
  EXPECT_THAT(unknown.error().message, HasSubstr("x0"));
  IncrementalSmootherConfig gauge;
  gauge.background_batch = false;
  gauge.batch.fixed = {X(0)};
  IncrementalSmoother fixed(gauge);
  GraphUpdate first;
  first.values.insert(X(0), SE3());
  first.values.insert(X(1), SE3());
  first.factors.emplace<BetweenFactorSE3>(X(0), X(1), SE3(), odometry);
  ASSERT_TRUE(fixed.update(first.factors, first.values).ok());
  EXPECT_FALSE(fixed.marginalize({X(0)}).ok());
  EXPECT_EQ(fixed.graph().size(), 1U);
}

}  // namespace
}  // namespace hanzo::fusion::graph
