// SE-Sync's global-optimality certificate on the published benchmarks: optima certified, a
// local minimum refused, and what cannot be certified said so.
#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/chordal_initialization.hpp"
#include "hanzo/fusion/graph/g2o_io.hpp"
#include "hanzo/fusion/graph/optimality_certificate.hpp"

namespace hanzo::fusion::graph {
namespace {

const std::string kData = std::string(HANZO_DATA_DIR) + "/pose_graph/se_sync/";

Values optimized(const PoseGraph& graph, Values values, PoseGraph::Objective objective) {
  BatchOptimizerConfig config;
  config.fixed = graph.fixed;
  EXPECT_TRUE(optimize(graph.factor_graph(objective).value(), values, config));
  return values;
}

OptimalityCertificate certify(const PoseGraph& graph, const Values& solution, const char* name) {
  const OptimalityCertificate certificate = certify_global_optimality(graph, solution).value();
  std::printf("%s: %s; min eigenvalue %.3g; objective %.6f -> %.6f (%d iterations), max change %.3g m %.3g rad, %.2f s\n", name,
              certificate.message.c_str(), certificate.min_eigenvalue, certificate.objective_given, certificate.objective_refined,
              certificate.refinement_iterations, certificate.max_translation_change, certificate.max_rotation_change, certificate.seconds);
  return certificate;
}

TEST(OptimalityCertificate, CertifiesIntelsOptimumFromEitherObjective) {
  const PoseGraph graph = read_g2o(kData + "intel.g2o").value();
  const OptimalityCertificate chordal = certify(graph, optimized(graph, graph.initial, PoseGraph::Objective::kChordal), "intel chordal");
  EXPECT_TRUE(chordal.certified) << chordal.message;
  EXPECT_GE(chordal.min_eigenvalue, -1e-6);
  EXPECT_NEAR(chordal.objective_refined, 52.3482, 1e-3);  // SE-Sync's published optimum
  EXPECT_LT(chordal.max_translation_change, 0.1);  // the optimizer stops at a relative cost decrease of 1e-6
  // g2o's geodesic optimum is a different point: refined onto SE-Sync's objective it is the
  // same certified optimum, a few centimetres away.
  const OptimalityCertificate geodesic = certify(graph, optimized(graph, graph.initial, PoseGraph::Objective::kGeodesic), "intel geodesic");
  EXPECT_TRUE(geodesic.certified) << geodesic.message;
  EXPECT_NEAR(geodesic.objective_refined, 52.3482, 1e-3);
  EXPECT_GT(geodesic.objective_given, geodesic.objective_refined);
}

TEST(OptimalityCertificate, RefusesALocalMinimum) {
  // Intel with its headings scrambled ends far from the optimum when optimized from its vertices.
  PoseGraph graph = read_g2o(kData + "intel.g2o").value();
  int vertex = 0;
  for (Key key : graph.vertices) {
    const SE2 pose = graph.initial.at<SE2>(key).value();
    graph.initial.insert(key, SE2(pose.angle() + 2.5 * std::sin(1.7 * vertex++), pose.translation()));
  }
  const OptimalityCertificate trapped = certify(graph, optimized(graph, graph.initial, PoseGraph::Objective::kChordal), "intel trapped");
  EXPECT_FALSE(trapped.certified);
  EXPECT_LT(trapped.min_eigenvalue, -1e-3);
  EXPECT_GT(trapped.objective_refined, 60.0);
  EXPECT_NE(trapped.message.find("not certified"), std::string::npos);
}

TEST(OptimalityCertificate, CertifiesTheParkingGarageIn3d) {
  const PoseGraph graph = read_g2o(kData + "parking-garage.g2o").value();
  const OptimalityCertificate garage = certify(graph, optimized(graph, graph.initial, PoseGraph::Objective::kGeodesic), "garage");
  EXPECT_TRUE(garage.certified) << garage.message;
  EXPECT_NEAR(garage.objective_refined, 1.2625, 1e-3);
}

TEST(OptimalityCertificate, SaysWhatItCannotCertify) {
  PoseGraph graph = read_g2o(kData + "intel.g2o").value();
  Values missing = graph.initial;
  Values partial;
  for (size_t i = 1; i < graph.vertices.size(); ++i) partial.insert(graph.vertices[i], missing.all().at(graph.vertices[i]));
  const auto refused = certify_global_optimality(graph, partial);
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("no pose for vertex"), std::string::npos);

  graph.fixed = {graph.vertices[0], graph.vertices[5]};
  const OptimalityCertificate constrained = certify_global_optimality(graph, graph.initial).value();
  EXPECT_FALSE(constrained.certified);
  EXPECT_NE(constrained.message.find("fixes 2 vertices"), std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion::graph
