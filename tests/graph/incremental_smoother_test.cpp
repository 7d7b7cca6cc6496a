// IncrementalSmoother: exact graphs stay exact update by update, a real data set added pose by
// pose in file order ends at the batch optimum, bad updates change nothing.

#include <chrono>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "hanzo/fusion/graph/g2o_io.hpp"
#include "hanzo/fusion/graph/incremental_smoother.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"

namespace hanzo::fusion::graph {
namespace {

using ::testing::HasSubstr;

const std::string kData = std::string(HANZO_DATA_DIR) + "/pose_graph/se_sync/";

// Exact odometry and loop closures between random 3D poses: every local update (no background
// batch) keeps every pose exact, so a loop closure never pulls anything off.
TEST(IncrementalSmoother, ExactGraphStaysExactWithLocalUpdatesOnly) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<SE3> truth;
  for (int i = 0; i < 60; ++i) {
    SE3::Tangent xi;
    for (int k = 0; k < 6; ++k) xi(k) = (k < 3 ? 3.0 : 0.5) * n(rng);
    truth.push_back(SE3::exp(xi));
  }
  const GaussianNoise noise = GaussianNoise::from_sigmas(Eigen::VectorXd::Constant(6, 0.1)).value();
  IncrementalSmootherConfig config;
  config.background_batch = false;
  config.batch.fixed = {X(0)};
  IncrementalSmoother smoother(config);
  for (int i = 0; i < 60; ++i) {
    GraphUpdate update;
    update.values.insert(X(i), i == 0 ? truth[0] : SE3(truth[i].rotation() * SO3::exp({0.1, -0.1, 0.2}), truth[i].translation() + Eigen::Vector3d(0.3, 0.0, -0.2)));
    if (i > 0) update.factors.emplace<BetweenFactorSE3>(X(i - 1), X(i), truth[i - 1].inverse() * truth[i], noise);
    if (i >= 10 && i % 5 == 0) update.factors.emplace<BetweenFactorSE3>(X(i - 10), X(i), truth[i - 10].inverse() * truth[i], noise);
    const IncrementalUpdateSummary summary = smoother.update(update.factors, update.values).value();
    EXPECT_LE(summary.optimized_variables, config.recent_variables + 3);  // bounded by the window, not the graph
    for (int k = 0; k <= i; ++k) {
      EXPECT_LT((truth[k].inverse() * smoother.estimate().at<SE3>(X(k)).value()).log().norm(), 1e-6) << i << " " << k;
    }
  }
}

// intel added pose by pose, each pose with its odometry and its loop closures back to earlier
// poses, new poses started from odometry: every update re-optimizes a small part, and after
// wait_for_batch() the estimate is the optimum (issue 6: the incremental run ends within 1 %).
// The latest estimate before that depends on when the background batches finished, which the
// scheduler decides: +0.1 to +0.7 % over 25 runs, idle or with other processes on the cores,
// but +5.8 % once in a CI run (a batch merged at an unlucky moment): only a sanity bound is
// asserted on it here; the bound the local updates keep on their own is asserted
// deterministically by the next test, without background batches.
struct IntelRun {
  double latest = 0.0;           // objective of the estimate right after the last update
  double final_objective = 0.0;  // after wait_for_batch()
  int max_optimized = 0, max_optimized_merging = 0;
  int batches_merged = 0;
};

IntelRun run_intel_pose_by_pose(const PoseGraph& graph, IncrementalSmootherConfig config) {
  const std::vector<GraphUpdate> updates = graph.incremental_updates(PoseGraph::Objective::kChordal).value();
  EXPECT_EQ(updates.size(), 1728u);
  config.batch.fixed = graph.fixed;
  IncrementalSmoother smoother(config);
  IntelRun run;
  for (const GraphUpdate& update : updates) {
    const IncrementalUpdateSummary summary = smoother.update(update.factors, update.values).value();
    int& bound = summary.batch_merged ? run.max_optimized_merging : run.max_optimized;
    bound = std::max(bound, summary.optimized_variables);
  }
  EXPECT_EQ(smoother.graph().size(), graph.edges.size());
  run.latest = se_sync_objective(graph, smoother.estimate()).value();
  EXPECT_TRUE(smoother.wait_for_batch().ok());
  run.final_objective = se_sync_objective(graph, smoother.estimate()).value();
  run.batches_merged = smoother.batches_merged();
  std::printf("intel incremental (background batches %s): latest %.4f, after wait %.4f, %d batches merged, at most %d variables an "
              "update (%d when merging)\n",
              config.background_batch ? "on" : "off", run.latest, run.final_objective, run.batches_merged, run.max_optimized,
              run.max_optimized_merging);
  return run;
}

TEST(IncrementalSmoother, IntelPoseByPoseEndsAtTheOptimum) {
  const PoseGraph graph = read_g2o(kData + "intel.g2o").value();
  const IncrementalSmootherConfig config;
  const IntelRun run = run_intel_pose_by_pose(graph, config);
  EXPECT_LT(run.latest, 1.15 * 52.3482);  // scheduler-dependent, see above
  EXPECT_NEAR(run.final_objective, 52.3482, 1e-3 * 52.3482);
  EXPECT_LT(run.max_optimized, 150);  // the window and the new factors' neighbourhoods, not the 1728 poses
  // A merging update also refits the variables added while the batch ran, at most merge_refit_variables.
  EXPECT_LT(run.max_optimized_merging, config.merge_refit_variables + 60);
}

TEST(IncrementalSmoother, IntelPoseByPoseLocalUpdatesAloneStayWithinFourPercent) {
  const PoseGraph graph = read_g2o(kData + "intel.g2o").value();
  IncrementalSmootherConfig config;
  config.background_batch = false;  // deterministic: no batch ever merges before wait_for_batch()
  const IntelRun run = run_intel_pose_by_pose(graph, config);
  EXPECT_EQ(run.max_optimized_merging, 0);
  EXPECT_LT(run.latest, 1.04 * 52.3482);
  EXPECT_NEAR(run.final_objective, 52.3482, 1e-3 * 52.3482);
  EXPECT_LT(run.max_optimized, 150);
}

TEST(IncrementalSmoother, RejectsBadUpdatesAndKeepsTheGraph) {
  IncrementalSmoother smoother;
  const GaussianNoise noise = GaussianNoise::from_sigmas(Eigen::Vector3d::Constant(0.1)).value();
  GraphUpdate first;
  first.values.insert(X(0), SE2());
  first.values.insert(X(1), SE2(0.1, {1.0, 0.0}));
  first.factors.emplace<BetweenFactorSE2>(X(0), X(1), SE2(0.0, {1.0, 0.0}), noise);
  ASSERT_TRUE(smoother.update(first.factors, first.values).ok());
  Values duplicate;
  duplicate.insert(X(1), SE2());
  EXPECT_THAT(smoother.update(FactorGraph{}, duplicate).error().message, HasSubstr("x1 already exists"));
  FactorGraph dangling;
  dangling.emplace<BetweenFactorSE2>(X(1), X(7), SE2(), noise);
  EXPECT_THAT(smoother.update(dangling, Values{}).error().message, HasSubstr("x7"));
  EXPECT_EQ(smoother.graph().size(), 1u);
  EXPECT_EQ(smoother.estimate().size(), 2u);
  EXPECT_TRUE(smoother.wait_for_batch().ok());
}

}  // namespace
}  // namespace hanzo::fusion::graph
