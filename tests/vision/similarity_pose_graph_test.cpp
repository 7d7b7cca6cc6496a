// The similarity pose graph of visual loop closure (src/vision/similarity_pose_graph.hpp).

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "similarity_pose_graph.hpp"

namespace hanzo::fusion::vision {
namespace {

Similarity random_similarity(std::mt19937_64& random, double scale) {
  std::normal_distribution<double> normal;
  const SE3 pose = SE3::exp((SE3::Tangent() << normal(random), normal(random), normal(random), 0.5 * normal(random), 0.5 * normal(random), 0.5 * normal(random)).finished());
  Similarity similarity = Similarity::from(pose);
  similarity.scale = scale;
  return similarity;
}

TEST(SimilarityPoseGraph, ComposeAndInverseAreConsistent) {
  std::mt19937_64 random(3);
  const Similarity a = random_similarity(random, 1.7), b = random_similarity(random, 0.4);
  const Eigen::Vector3d p(0.3, -1.2, 2.5);
  EXPECT_LT(((a * b) * p - a * (b * p)).norm(), 1e-12);
  EXPECT_LT((a.inverse() * (a * p) - p).norm(), 1e-12);
  EXPECT_NEAR((a * a.inverse()).scale, 1.0, 1e-12);
}

// A ring of ten keyframes whose scale grows along the chain (monocular drift): the graph built
// from the true relative similarities, started from poses that drifted, returns to the truth.
TEST(SimilarityPoseGraph, ARingStartedFromDriftedPosesReturnsToTheTruth) {
  std::map<int, Similarity> truth;
  for (int i = 0; i < 10; ++i) {
    const double angle = 2 * M_PI * i / 10;
    truth[i] = {Eigen::Quaterniond(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ())), Eigen::Vector3d(5 * std::cos(angle), 5 * std::sin(angle), 0.1 * i),
                std::pow(1.08, i)};
  }
  std::vector<SimilarityEdge> edges;
  for (int i = 0; i < 10; ++i) edges.push_back({i, (i + 1) % 10, truth[i].inverse() * truth[(i + 1) % 10], 1.0});
  std::map<int, Similarity> estimate = truth;
  std::mt19937_64 random(5);
  for (int i = 1; i < 10; ++i) estimate[i] = truth[i] * random_similarity(random, 1.0 + 0.02 * i);
  const SimilarityPoseGraphSummary summary = optimize_similarity_pose_graph(estimate, edges, {0}, false, 100);
  EXPECT_LT(summary.final_cost, 1e-12);
  EXPECT_LT(summary.final_cost, summary.initial_cost);
  for (int i = 0; i < 10; ++i) {
    EXPECT_LT((estimate[i].translation - truth[i].translation).norm(), 1e-5) << i;
    EXPECT_LT(estimate[i].rotation.angularDistance(truth[i].rotation), 1e-6) << i;
    EXPECT_NEAR(estimate[i].scale, truth[i].scale, 1e-6) << i;
  }
  // Fixed scale (stereo): scales stay where they start.
  std::map<int, Similarity> rigid = truth;
  for (int i = 1; i < 10; ++i) rigid[i].translation += Eigen::Vector3d(0.1, 0, 0);
  optimize_similarity_pose_graph(rigid, edges, {0}, true, 50);
  for (int i = 0; i < 10; ++i) EXPECT_DOUBLE_EQ(rigid[i].scale, truth[i].scale);
}

}  // namespace
}  // namespace hanzo::fusion::vision
