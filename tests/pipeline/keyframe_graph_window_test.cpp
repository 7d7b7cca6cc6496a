// KeyframeGraph with a sliding window (window_keyframes): keyframes joined by a weak relative
// motion and by landmarks each seen from a few keyframes (body-frame point measurements), around
// a loop. Old keyframes keep only their poses (a pose graph), the graph stays bounded apart from
// them, the poses stay as accurate as the full graph's, and a loop closure to a keyframe that
// left the window long ago still bends the trajectory onto the truth.

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "graph/jacobian_check.hpp"
#include "hanzo/fusion/graph/imu_factors.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/graph/pose_factors.hpp"
#include "hanzo/fusion/pipeline/keyframe_graph.hpp"

namespace hanzo::fusion::pipeline {
namespace {

// A world point seen from the body: r = (R^T (p - t) - z) / sigma, right perturbation of the pose.
class BodyPointFactor final : public graph::Factor {
 public:
  BodyPointFactor(graph::Key pose, graph::Key point, Eigen::Vector3d measured, double sigma)
      : Factor({pose, point}), measured_(measured), sigma_(sigma) {}
  int dimension() const override { return 3; }
  Result<Eigen::VectorXd> evaluate(const graph::Values& values, std::vector<Eigen::MatrixXd>* jacobians) const override {
    SE3 T;
    HANZO_ASSIGN_OR_RETURN(T, values.at<SE3>(keys()[0]));
    Eigen::Vector3d p;
    HANZO_ASSIGN_OR_RETURN(p, values.at<Eigen::Vector3d>(keys()[1]));
    const Eigen::Matrix3d Rt = T.rotation().matrix().transpose();
    const Eigen::Vector3d in_body = Rt * (p - T.translation());
    if (jacobians) {
      Eigen::MatrixXd d_pose(3, 6);
      d_pose << -Eigen::Matrix3d::Identity(), SO3::hat(in_body);
      *jacobians = {d_pose / sigma_, Eigen::MatrixXd(Rt / sigma_)};
    }
    return Eigen::VectorXd((in_body - measured_) / sigma_);
  }

 private:
  Eigen::Vector3d measured_;
  double sigma_;
};

TEST(KeyframeGraphWindow, BodyPointFactorJacobians) {
  graph::Values values;
  values.insert(graph::X(0), SE3(SO3::exp({0.2, -0.1, 0.7}), Eigen::Vector3d(1, 2, 3)));
  values.insert(graph::L(0), Eigen::Vector3d(4, -1, 2));
  graph::expect_jacobians_match(BodyPointFactor(graph::X(0), graph::L(0), Eigen::Vector3d(0.5, 0.2, 0.1), 0.05), values);
}

struct LoopRun {
  double rmse = 0.0;              // keyframe positions against the truth, m
  std::size_t factors = 0;        // at the end
  std::size_t variables = 0;
  bool old_landmark_left = false;
  bool old_pose_stays = false;
};

// 120 keyframes around a 20 m circle; each sees the 6 landmarks placed along the next few metres
// (each landmark from 4 keyframes, 5 cm noise) and has a velocity with a prior (a variable beyond
// its pose); the relative motion is weak (x10 sigma). With `close_loop` the last keyframe is
// matched to the first (2 cm).
LoopRun run_loop(int window, bool close_loop) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  constexpr int kKeyframes = 120;
  constexpr double kRadius = 20.0;
  auto truth = [&](int k) {
    const double angle = 2.0 * M_PI * k / kKeyframes;
    return SE3(SO3::exp({0.0, 0.0, angle + M_PI / 2}), Eigen::Vector3d(kRadius * std::cos(angle), kRadius * std::sin(angle), 0.0));
  };
  std::vector<Eigen::Vector3d> landmarks;
  for (int j = 0; j < kKeyframes + 4; ++j) {
    const double angle = 2.0 * M_PI * (j + 2) / kKeyframes;
    landmarks.emplace_back((kRadius + 3.0 * (j % 2 ? 1 : -1)) * std::cos(angle), (kRadius + 3.0 * (j % 2 ? 1 : -1)) * std::sin(angle), 1.0 + (j % 3));
  }
  KeyframeGraphConfig config;
  config.smoother.background_batch = false;
  config.batch_on_loop_closure = true;
  config.window_keyframes = window;
  KeyframeGraph graph(config);
  Eigen::Matrix<double, 6, 6> relative = Eigen::Matrix<double, 6, 6>::Identity();
  relative.topLeftCorner<3, 3>() *= 0.02 * 0.02;
  relative.bottomRightCorner<3, 3>() *= 0.002 * 0.002;
  SE3 odometry = truth(0);
  for (int k = 0; k < kKeyframes; ++k) {
    msgs::Keyframe keyframe;
    keyframe.keyframe_id = static_cast<uint64_t>(k);
    keyframe.timestamp = Timestamp::from_seconds(100.0 + k);
    if (k > 0) {
      SE3::Tangent noise;
      for (int i = 0; i < 6; ++i) noise(i) = (i < 3 ? 0.02 : 0.002) * n(rng);
      const SE3 measured = truth(k - 1).inverse() * truth(k) * SE3::exp(noise);
      odometry = odometry * measured;
      keyframe.previous_keyframe_id = static_cast<uint64_t>(k - 1);
      keyframe.T_previous_current = msgs::Pose::from_se3(measured);
      keyframe.relative_covariance = relative;
    }
    keyframe.T_world_body = msgs::Pose::from_se3(odometry);
    keyframe.pose_covariance = Eigen::Matrix<double, 6, 6>::Identity() * 1e-6;
    EXPECT_TRUE(graph.add_keyframe(keyframe, 100.0).ok());
    graph::GraphUpdate update;
    update.values.insert(graph::V(keyframe.keyframe_id), Eigen::Vector3d::Zero());
    update.factors.emplace<graph::PriorFactorVector3>(graph::V(keyframe.keyframe_id), Eigen::Vector3d::Zero(),
                                                      graph::GaussianNoise::from_sigmas(Eigen::Vector3d::Constant(1.0)).value());
    for (int j = std::max(0, k - 3); j <= k; ++j) {
      // Landmark j is seen from keyframes j..j+3; it starts where the odometry puts it.
      const Eigen::Vector3d seen = truth(k).inverse() * landmarks[static_cast<std::size_t>(j)] + 0.05 * Eigen::Vector3d(n(rng), n(rng), n(rng));
      const graph::Key key = graph::L(static_cast<uint64_t>(j));
      if (j == k) update.values.insert(key, odometry * seen);
      update.factors.emplace<BodyPointFactor>(graph::X(keyframe.keyframe_id), key, seen, 0.05);
    }
    graph.add_factors(update);
    if (close_loop && k == kKeyframes - 1) {
      Eigen::Matrix<double, 6, 6> closure = Eigen::Matrix<double, 6, 6>::Identity() * 0.02 * 0.02;
      EXPECT_TRUE(graph.add_loop_closure(0, keyframe.keyframe_id, truth(0).inverse() * truth(k), closure).ok());
    }
    const Result<KeyframeGraphUpdate> processed = graph.process();
    EXPECT_TRUE(processed.ok()) << processed.error().message;
    if (processed && window > 0 && k >= window) {
      EXPECT_EQ(processed->keyframes_left_window, 1) << k;
    }
  }
  LoopRun run;
  double squared = 0.0;
  for (int k = 0; k < kKeyframes; ++k) squared += (graph.optimized_pose(static_cast<uint64_t>(k))->translation() - truth(k).translation()).squaredNorm();
  run.rmse = std::sqrt(squared / kKeyframes);
  run.factors = graph.smoother().graph().size();
  run.variables = graph.smoother().estimate().size();
  run.old_landmark_left = !graph.smoother().estimate().exists(graph::L(3)) && !graph.smoother().estimate().exists(graph::V(3));
  run.old_pose_stays = graph.smoother().estimate().exists(graph::X(3));
  return run;
}

TEST(KeyframeGraphWindow, OldKeyframesKeepTheirPosesAndTheGraphStaysBounded) {
  const LoopRun full = run_loop(0, false);
  const LoopRun windowed = run_loop(10, false);
  EXPECT_TRUE(windowed.old_landmark_left);
  EXPECT_TRUE(windowed.old_pose_stays);
  // Per old keyframe: its pose, a link, its prior-less pose-graph node; the window's variables.
  EXPECT_LT(windowed.variables, 120U + 10U * 2U + 20U);
  EXPECT_EQ(full.variables, 3U * 120U);
  EXPECT_LT(windowed.factors, full.factors / 3);
  EXPECT_LT(windowed.rmse, 1.5 * full.rmse + 0.01) << "full " << full.rmse << " m, window " << windowed.rmse << " m";
  RecordProperty("full_rmse_m", std::to_string(full.rmse));
  RecordProperty("window_rmse_m", std::to_string(windowed.rmse));
}

TEST(KeyframeGraphWindow, ALoopClosureToAKeyframeThatLeftTheWindowBendsTheTrajectory) {
  const LoopRun open = run_loop(10, false);
  const LoopRun closed = run_loop(10, true);
  EXPECT_LT(closed.rmse, 0.5 * open.rmse) << "open " << open.rmse << " m, closed " << closed.rmse << " m";
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
