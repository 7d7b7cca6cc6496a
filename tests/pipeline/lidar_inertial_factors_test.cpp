// The keyframe graph's LiDAR-inertial factors: IMU preintegration and the LiDAR odometry's
// relative motions (sweeps between the keyframes, in a tilted odometry frame of their own) put
// keyframes given 10 cm / 1 degree off back onto the truth's motion and estimate the velocities;
// a LiDAR map started again or a keyframe without a sweep nearby breaks the LiDAR chain only.

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "circle_motion.hpp"
#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/pipeline/keyframe_graph.hpp"
#include "lidar_inertial_factors.hpp"

namespace hanzo::fusion::pipeline {
namespace {

using namespace circle_motion;

const SE3 kBodyToLidar(SO3::exp(Eigen::Vector3d(0.0, 0.05, 0.3)), Eigen::Vector3d(0.5, 0.0, 1.0));

LidarInertialFactors make_factors() {
  graph::ImuPreintegrationConfig imu;
  imu.process_noise_accel = 0.02;
  imu.process_noise_gyro = 0.002;
  imu.sample_interval = 0.005;
  imu.gravity = kGravity;
  return LidarInertialFactors(kBodyToLidar, imu, 1e-3, 1e-4);
}

struct Drive {
  std::vector<msgs::Keyframe> keyframes;
  std::vector<LidarInertialFactors::KeyframeFactors> factors;
  std::vector<SE3> truth;
};

struct DriveOptions {
  double seconds = 6.0;
  double sweep_delay = 0.02;             // s: sweep middles 0.03 + 0.1 n s (a keyframe's sweep after it)
  double map_restart_at = 1e9;           // s: the sweep at this time starts a new LiDAR map
  double sweeps_missing_from = 1e9;      // s: no sweeps in [from, to)
  double sweeps_missing_to = 1e9;
};

// Adds a keyframe with its factors, as the Session does.
void add_to_graph(LidarInertialFactors& factors, KeyframeGraph& graph, Drive& flight, const msgs::Keyframe& keyframe) {
  flight.factors.push_back(factors.keyframe(keyframe, graph::ImuBias{}, graph.smoother().estimate()));
  const LidarInertialFactors::KeyframeFactors& made = flight.factors.back();
  EXPECT_TRUE(graph.add_keyframe(keyframe, made.imu_factor && made.lidar_factor ? factors.config().odometry_covariance_scale : 1.0).ok());
  graph.add_factors(made.update);
  EXPECT_TRUE(graph.process().ok());
}

// IMU at 200 Hz, sweeps at 10 Hz (their middles sweep_delay before the IMU sample that ends
// them), keyframes every 0.5 s from 0.005 s
// at IMU times with poses 10 cm / 1 degree off the truth and velocities 3 cm/s off. Each
// keyframe goes into the graph 0.3 s of data later (the Frontend's lag window), with its factors.
Drive drive(LidarInertialFactors& factors, KeyframeGraph& graph, const DriveOptions& options) {
  std::mt19937_64 random(3);
  // The odometry's map frame: tilted and turned against the world (only relative motion is used).
  SE3 T_odometry_world(SO3::exp(Eigen::Vector3d(0.02, -0.01, 0.7)), Eigen::Vector3d(4.0, -1.0, 0.5));
  Drive flight;
  const int samples = static_cast<int>(std::lround(options.seconds / 0.005));
  for (int k = 1; k <= samples; ++k) {
    const double t = 0.005 * k;
    factors.add_imu(imu_sample(t, 0.005));
    if (k % 20 == 10) {
      const double middle = t - options.sweep_delay;
      const bool restart = std::abs(middle - options.map_restart_at) < 1e-6;
      if (restart) T_odometry_world = SE3(SO3::exp(Eigen::Vector3d(0.0, 0.0, -1.0)), Eigen::Vector3d(-2.0, 3.0, 0.0));
      if (middle > 0.0 && !(middle >= options.sweeps_missing_from && middle < options.sweeps_missing_to)) {
        factors.add_sweep(Timestamp::from_seconds(kStart + middle), T_odometry_world * true_pose(middle) * kBodyToLidar,
                          Eigen::Matrix<double, 6, 6>::Identity() * 1e-8, restart);
      }
    }
    if (flight.factors.size() < flight.keyframes.size() && t >= flight.keyframes[flight.factors.size()].timestamp.seconds() - kStart + 0.3) {
      add_to_graph(factors, graph, flight, flight.keyframes[flight.factors.size()]);
    }
    if (k % 100 != 1) continue;
    const msgs::Keyframe keyframe = noisy_keyframe(flight.keyframes.size(), t, flight.keyframes.empty() ? nullptr : &flight.keyframes.back(), 0.03, random);
    const SE3 T_world_body = true_pose(t);
    flight.truth.push_back(T_world_body);
    flight.keyframes.push_back(keyframe);
  }
  while (flight.factors.size() < flight.keyframes.size()) add_to_graph(factors, graph, flight, flight.keyframes[flight.factors.size()]);
  return flight;
}

KeyframeGraph make_graph() {
  KeyframeGraphConfig config;
  config.smoother.background_batch = false;
  return KeyframeGraph(config);
}

TEST(LidarInertialFactors, ImuAndLidarFactorsPutKeyframesBackOntoTheTruth) {
  // Sweeps 25 ms after each keyframe, then 25 ms before.
  for (const double sweep_delay : {0.02, 0.07}) {
  SCOPED_TRACE(sweep_delay);
  LidarInertialFactors factors = make_factors();
  KeyframeGraph graph = make_graph();
  const Drive flight = drive(factors, graph, {6.0, sweep_delay});
  ASSERT_EQ(flight.keyframes.size(), 12u);
  ASSERT_TRUE(graph.smoother().wait_for_batch().ok());
  for (size_t k = 0; k < flight.keyframes.size(); ++k) {
    EXPECT_EQ(flight.factors[k].imu_factor, k > 0) << "keyframe " << k;
    EXPECT_EQ(flight.factors[k].lidar_factor, k > 0) << "keyframe " << k;
  }
  // Given 10 cm / 1 degree off: each relative motion within 2 mm and 0.02 degrees, every pose
  // within 1 cm of the truth (the first keyframe's prior fixes the frame), velocities 2 cm/s.
  for (size_t k = 1; k < flight.keyframes.size(); ++k) {
    const SE3 relative = graph.optimized_pose(k - 1).value().inverse() * graph.optimized_pose(k).value();
    const SE3 true_relative = flight.truth[k - 1].inverse() * flight.truth[k];
    EXPECT_LT((relative.translation() - true_relative.translation()).norm(), 0.002) << "keyframe " << k;
    EXPECT_LT((relative.rotation().inverse() * true_relative.rotation()).log().norm(), 0.02 * M_PI / 180.0) << "keyframe " << k;
    EXPECT_LT((graph.optimized_pose(k).value().translation() - flight.truth[k].translation()).norm(), 0.01) << "keyframe " << k;
    const Eigen::Vector3d velocity = graph.smoother().estimate().at<Eigen::Vector3d>(graph::V(k)).value();
    EXPECT_LT((velocity - true_velocity(flight.keyframes[k].timestamp.seconds() - kStart)).norm(), 0.02) << "keyframe " << k;
  }
  }
}

TEST(LidarInertialFactors, ANewLidarMapBreaksTheLidarChainOnly) {
  LidarInertialFactors factors = make_factors();
  KeyframeGraph graph = make_graph();
  const Drive flight = drive(factors, graph, {4.0, 0.02, 1.83});  // the sweep at 1.83 s starts a new map
  ASSERT_EQ(flight.keyframes.size(), 8u);
  for (size_t k = 1; k < flight.keyframes.size(); ++k) {
    EXPECT_TRUE(flight.factors[k].imu_factor) << "keyframe " << k;
    // The keyframe at 2.005 s takes the new map's sweep at 2.03 s: no motion from the old map's.
    EXPECT_EQ(flight.factors[k].lidar_factor, k != 4) << "keyframe " << k;
  }
}

TEST(LidarInertialFactors, AKeyframeWithoutASweepNearbyIsBridged) {
  LidarInertialFactors factors = make_factors();
  KeyframeGraph graph = make_graph();
  const Drive flight = drive(factors, graph, {4.0, 0.02, 1e9, 1.3, 1.8});  // no sweeps for 0.5 s around the keyframe at 1.505 s
  ASSERT_EQ(flight.keyframes.size(), 8u);
  EXPECT_FALSE(flight.factors[3].lidar_factor);
  // The next keyframe's LiDAR motion spans from keyframe 2 (the last with a sweep).
  ASSERT_TRUE(flight.factors[4].lidar_factor);
  bool bridged = false;
  for (const graph::FactorPointer& factor : flight.factors[4].update.factors.factors()) {
    bridged = bridged || (factor->keys() == std::vector<graph::Key>{graph::X(2), graph::X(4)});
  }
  EXPECT_TRUE(bridged);
  ASSERT_TRUE(graph.smoother().wait_for_batch().ok());
  EXPECT_LT((graph.optimized_pose(3).value().translation() - flight.truth[3].translation()).norm(), 0.01);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
