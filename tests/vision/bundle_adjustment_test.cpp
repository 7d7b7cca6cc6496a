#include "hanzo/fusion/vision/bundle_adjustment.hpp"

#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/graph/batch_optimizer.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/graph/projection_factors.hpp"

namespace hanzo::fusion::vision {
namespace {

PinholeCamera distorted_camera() {
  PinholeCamera camera;
  camera.fx = 460.0;
  camera.fy = 455.0;
  camera.cx = 320.0;
  camera.cy = 240.0;
  camera.distortion = PinholeCamera::Distortion::kRadtan;
  camera.coefficients = {-0.28, 0.07, 0.0002, 0.00002, 0.0};
  return camera;
}

// A stereo rig on a body moving along x, points on a wall 4-8 m ahead, the pixels with 0.5 px
// noise and every 25th observation an outlier 20 px off; the start perturbed by 5 cm / 1 degree
// and 10 cm per point.
struct Scene {
  BundleProblem truth;
  BundleProblem start;
};

Scene make_scene(std::uint32_t seed) {
  std::mt19937 random(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Scene scene;
  BundleProblem& truth = scene.truth;
  truth.cameras.push_back({distorted_camera(), SE3(SO3::exp(Eigen::Vector3d(0.01, -0.02, 0.005)), Eigen::Vector3d(0.02, 0.0, 0.01))});
  truth.cameras.push_back({distorted_camera(), SE3(SO3::exp(Eigen::Vector3d(0.0, 0.01, 0.0)), Eigen::Vector3d(0.12, 0.0, 0.0))});
  for (int k = 0; k < 8; ++k) {
    truth.T_world_body.push_back(SE3(SO3::exp(Eigen::Vector3d(0.0, 0.03 * k, 0.01 * k)), Eigen::Vector3d(0.3 * k, 0.05 * std::sin(k), 0.0)));
    truth.pose_fixed.push_back(k == 0);
  }
  for (int j = 0; j < 300; ++j) truth.points_world.emplace_back(1.2 + 2.5 * uniform(random), 1.5 * uniform(random), 6.0 + 2.0 * uniform(random));
  int count = 0;
  for (int j = 0; j < 300; ++j) {
    for (int k = 0; k < 8; ++k) {
      for (int c = 0; c < 2; ++c) {
        if ((j + k + c) % 3 == 0) continue;  // not every point in every image
        BundleObservation observation{k, j, c, Eigen::Vector2d::Zero(), 1.0 + 0.2 * (j % 3)};
        const SE3 T_world_camera = truth.T_world_body[static_cast<std::size_t>(k)] * truth.cameras[static_cast<std::size_t>(c)].T_body_camera;
        const std::optional<Eigen::Vector2d> pixel = truth.cameras[static_cast<std::size_t>(c)].camera.project(T_world_camera.inverse().act(truth.points_world[static_cast<std::size_t>(j)]));
        if (!pixel) continue;
        observation.pixel = *pixel + 0.5 * Eigen::Vector2d(normal(random), normal(random));
        if (++count % 25 == 0) observation.pixel += Eigen::Vector2d(20.0, -15.0);
        truth.observations.push_back(observation);
      }
    }
  }
  scene.start = truth;
  for (std::size_t k = 1; k < scene.start.T_world_body.size(); ++k) {
    SE3::Tangent perturbation;
    perturbation << 0.05 * normal(random), 0.05 * normal(random), 0.05 * normal(random), 0.017 * normal(random), 0.017 * normal(random), 0.017 * normal(random);
    scene.start.T_world_body[k] = scene.start.T_world_body[k] * SE3::exp(perturbation);
  }
  for (Eigen::Vector3d& point : scene.start.points_world) point += 0.1 * Eigen::Vector3d(normal(random), normal(random), normal(random));
  return scene;
}

TEST(BundleAdjustment, JacobiansMatchNumericalDifferentiation) {
  const Scene scene = make_scene(1);
  for (std::size_t i = 0; i < scene.start.observations.size(); i += 97) {
    const BundleObservation& observation = scene.start.observations[i];
    const SE3& pose = scene.start.T_world_body[static_cast<std::size_t>(observation.pose)];
    const Eigen::Vector3d& point = scene.start.points_world[static_cast<std::size_t>(observation.point)];
    const BundleCamera& camera = scene.start.cameras[static_cast<std::size_t>(observation.camera)];
    Eigen::Vector2d residual;
    Eigen::Matrix<double, 2, 6> d_pose;
    Eigen::Matrix<double, 2, 3> d_point;
    ASSERT_TRUE(bundle_residual(pose, point, camera, observation, residual, &d_pose, &d_point));
    constexpr double h = 1e-6;
    for (int d = 0; d < 6; ++d) {
      SE3::Tangent step = SE3::Tangent::Zero();
      step[d] = h;
      Eigen::Vector2d plus, minus;
      ASSERT_TRUE(bundle_residual(pose * SE3::exp(step), point, camera, observation, plus, nullptr, nullptr));
      ASSERT_TRUE(bundle_residual(pose * SE3::exp(-step), point, camera, observation, minus, nullptr, nullptr));
      EXPECT_LT(((plus - minus) / (2.0 * h) - d_pose.col(d)).norm(), 1e-5 * (1.0 + d_pose.col(d).norm())) << "pose column " << d << ", observation " << i;
    }
    for (int d = 0; d < 3; ++d) {
      Eigen::Vector3d step = Eigen::Vector3d::Zero();
      step[d] = h;
      Eigen::Vector2d plus, minus;
      ASSERT_TRUE(bundle_residual(pose, point + step, camera, observation, plus, nullptr, nullptr));
      ASSERT_TRUE(bundle_residual(pose, point - step, camera, observation, minus, nullptr, nullptr));
      EXPECT_LT(((plus - minus) / (2.0 * h) - d_point.col(d)).norm(), 1e-5 * (1.0 + d_point.col(d).norm())) << "point column " << d << ", observation " << i;
    }
  }
}

// The same window solved by the graph module's general solver (Ceres, projection factors with
// the Huber kernel): both reach the same minimum, near the truth, the fixed pose held exactly.
TEST(BundleAdjustment, ReachesTheGeneralSolversMinimum) {
  const Scene scene = make_scene(2);
  BundleProblem problem = scene.start;
  BundleAdjustmentConfig config;
  config.max_iterations = 50;
  const Result<BundleAdjustmentSummary> summary = bundle_adjust(problem, config);
  ASSERT_TRUE(summary) << summary.error().message;
  EXPECT_TRUE(summary.value().converged);
  EXPECT_LT(summary.value().final_cost, 0.1 * summary.value().initial_cost);

  graph::FactorGraph factors;
  graph::Values values;
  const graph::RobustKernel huber{graph::RobustKernel::Type::kHuber, config.huber_threshold};
  for (std::size_t k = 0; k < scene.start.T_world_body.size(); ++k) values.insert(graph::X(k), scene.start.T_world_body[k]);
  for (std::size_t j = 0; j < scene.start.points_world.size(); ++j) values.insert(graph::L(j), scene.start.points_world[j]);
  for (const BundleObservation& observation : scene.start.observations) {
    const BundleCamera& camera = scene.start.cameras[static_cast<std::size_t>(observation.camera)];
    factors.emplace_robust<graph::ProjectionFactor>(huber, graph::X(static_cast<std::uint64_t>(observation.pose)), graph::L(static_cast<std::uint64_t>(observation.point)),
                                                    observation.pixel, camera.camera, camera.T_body_camera,
                                                    graph::GaussianNoise::from_sigmas(Eigen::Vector2d::Constant(observation.sigma_px)).value());
  }
  graph::BatchOptimizerConfig general;
  general.max_iterations = 50;
  general.fixed.push_back(graph::X(0));
  const Result<graph::OptimizationSummary> general_summary = graph::optimize(factors, values, general);
  ASSERT_TRUE(general_summary);
  EXPECT_NEAR(summary.value().final_cost, 0.5 * general_summary.value().final_chi2, 1e-6 * summary.value().final_cost);

  EXPECT_EQ(problem.T_world_body[0].translation(), scene.start.T_world_body[0].translation());
  EXPECT_EQ(problem.T_world_body[0].rotation().matrix(), scene.start.T_world_body[0].rotation().matrix());
  for (std::size_t k = 0; k < problem.T_world_body.size(); ++k) {
    const SE3 general_pose = values.at<SE3>(graph::X(k)).value();
    EXPECT_LT((problem.T_world_body[k].translation() - general_pose.translation()).norm(), 1e-6) << "pose " << k;
    EXPECT_LT((problem.T_world_body[k].rotation().inverse() * general_pose.rotation()).log().norm(), 1e-7) << "pose " << k;
    EXPECT_LT((problem.T_world_body[k].translation() - scene.truth.T_world_body[k].translation()).norm(), 0.03) << "pose " << k;
  }
  for (std::size_t j = 0; j < problem.points_world.size(); ++j) {
    EXPECT_LT((problem.points_world[j] - values.at<Eigen::Vector3d>(graph::L(j)).value()).norm(), 1e-5) << "point " << j;
  }
}

TEST(BundleAdjustment, RefusesBadInputAndLeavesTheProblemAsItWas) {
  const Scene scene = make_scene(3);
  const auto refused = [&](BundleProblem problem, const std::string& says) {
    const BundleProblem before = problem;
    const Result<BundleAdjustmentSummary> summary = bundle_adjust(problem);
    ASSERT_FALSE(summary) << "expected a refusal saying " << says;
    EXPECT_NE(summary.error().message.find(says), std::string::npos) << summary.error().message;
    EXPECT_EQ(problem.points_world, before.points_world);
  };
  BundleProblem problem = scene.start;
  problem.observations[5].point = 300;
  refused(problem, "observation 5 names pose");
  problem = scene.start;
  problem.observations[7].sigma_px = 0.0;
  refused(problem, "observation 7: sigma 0");
  problem = scene.start;
  problem.pose_fixed.pop_back();
  refused(problem, "7 fixed flags for 8 poses");
  problem = scene.start;
  problem.points_world[problem.observations[3].point].z() = -5.0;
  refused(problem, "is behind camera");
  BundleAdjustmentConfig config;
  config.huber_threshold = 0.0;
  problem = scene.start;
  EXPECT_FALSE(bundle_adjust(problem, config));
}

}  // namespace
}  // namespace hanzo::fusion::vision
