// The keyframe graph's visual-inertial factors: IMU preintegration between keyframes and
// landmarks from tracked features put keyframes given 10 cm / 1 degree off back onto the truth's
// motion;
// an IMU gap starts a new chain; tracks from before an odometry restart are not triangulated with
// the ones after it.

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/graph/keys.hpp"
#include "hanzo/fusion/pipeline/keyframe_graph.hpp"
#include "circle_motion.hpp"
#include "visual_inertial_factors.hpp"

namespace hanzo::fusion::pipeline {
namespace {

// The body circles (circle_motion.hpp), facing along its motion, with a forward camera; points
// on a cylinder of radius 6 m around the circle's centre.
using namespace circle_motion;
constexpr double kFocal = 400.0;

SE3 body_to_camera() {  // camera z forward (body x), x right (body -y), y down (body -z)
  Eigen::Matrix3d R_body_camera;
  R_body_camera << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  return SE3(SO3::from_matrix(R_body_camera), Eigen::Vector3d(0.1, 0.0, 0.05));
}

std::vector<Eigen::Vector3d> cylinder_points() {
  std::vector<Eigen::Vector3d> points;
  for (int i = 0; i < 360; ++i) {
    const double angle = 2.0 * M_PI * i / 360.0;
    points.emplace_back(6.0 * std::cos(angle), 6.0 * std::sin(angle), -1.5 + 3.0 * ((i * 7) % 11) / 10.0);
  }
  return points;
}

std::vector<vision::FeatureObservation> observe(const SE3& T_world_body, const std::vector<Eigen::Vector3d>& points, std::mt19937_64& random) {
  std::normal_distribution<double> pixel_noise(0.0, 0.5 / kFocal);
  const SE3 T_camera_world = (T_world_body * body_to_camera()).inverse();
  std::vector<vision::FeatureObservation> observations;
  for (size_t j = 0; j < points.size(); ++j) {
    const Eigen::Vector3d p = T_camera_world * points[j];
    if (p.z() < 0.5 || std::abs(p.x() / p.z()) > 0.8 || std::abs(p.y() / p.z()) > 0.6) continue;
    observations.push_back({j, 0, Eigen::Vector2d(p.x() / p.z() + pixel_noise(random), p.y() / p.z() + pixel_noise(random))});
  }
  return observations;
}

VisualInertialFactors make_factors() {
  graph::ImuPreintegrationConfig imu;
  imu.process_noise_accel = 0.02;
  imu.process_noise_gyro = 0.002;
  imu.sample_interval = 0.005;
  imu.gravity = kGravity;
  VisualInertialFactorsConfig config;
  config.pixel_sigma = 0.5;  // as simulated
  return VisualInertialFactors({{body_to_camera(), kFocal}}, imu, 1e-3, 1e-4, config);
}

struct Flight {
  std::vector<msgs::Keyframe> keyframes;
  std::vector<VisualInertialFactors::KeyframeFactors> factors;
  std::vector<SE3> truth;
};

// Feeds `seconds` of flight: IMU at 200 Hz (skipping [gap_from, gap_to)), frames at 20 Hz,
// keyframes every 0.5 s (5 ms after a frame) with poses 10 cm / 1 degree off the truth. With a
// graph, each keyframe's factors go into it at once and its estimates are the lookups; without,
// the truth is.
Flight fly(VisualInertialFactors& factors, double seconds, KeyframeGraph* graph = nullptr, double gap_from = 1e9, double gap_to = 1e9,
           double restart_at = 1e9, bool landmarks_behind = false) {
  std::mt19937_64 random(7);
  const std::vector<Eigen::Vector3d> points = cylinder_points();
  // The odometry's own world: anywhere (only its local geometry is used).
  SE3 T_odometry_world(SO3::exp(Eigen::Vector3d(0.1, -0.2, 1.0)), Eigen::Vector3d(5.0, -2.0, 1.0));
  Flight flight;
  const int samples = static_cast<int>(std::lround(seconds / 0.005));
  for (int k = 1; k <= samples; ++k) {
    const double t = 0.005 * k;
    if (t < gap_from || t >= gap_to) factors.add_imu(imu_sample(t, 0.005));
    if (k % 10 == 0) {
      if (std::abs(t - restart_at) < 1e-9) {
        factors.odometry_restarted();
        T_odometry_world = SE3(SO3::exp(Eigen::Vector3d(0.0, 0.0, 2.0)), Eigen::Vector3d(-3.0, 4.0, 0.0));
      }
      factors.add_frame(Timestamp::from_seconds(100.0 + t), T_odometry_world * true_pose(t), observe(true_pose(t), points, random));
    }
    if (k % 100 != 1) continue;
    const msgs::Keyframe keyframe = noisy_keyframe(flight.keyframes.size(), t, flight.keyframes.empty() ? nullptr : &flight.keyframes.back(), 0.1, random);
    const SE3 T_world_body = true_pose(t);
    flight.truth.push_back(T_world_body);
    // Without a graph, the truth as its estimate (landmarks_behind: mirrored behind the camera).
    graph::Values truth;
    for (size_t i = 0; i + 1 < flight.truth.size(); ++i) {
      truth.insert(graph::X(i), flight.truth[i]);
      truth.insert(graph::V(i), true_velocity(flight.keyframes[i].timestamp.seconds() - 100.0));
      truth.insert(graph::B(i), graph::ImuBias{});
    }
    const SE3 T_world_camera = T_world_body * body_to_camera();
    for (size_t j = 0; j < points.size(); ++j) {
      Eigen::Vector3d p_camera = T_world_camera.inverse() * points[j];
      if (landmarks_behind) p_camera.z() = -p_camera.z();
      truth.insert(graph::L(j), T_world_camera * p_camera);
    }
    flight.factors.push_back(factors.keyframe(keyframe, graph::ImuBias{}, graph != nullptr ? graph->smoother().estimate() : truth));
    flight.keyframes.push_back(keyframe);
    if (graph != nullptr) {
      msgs::Keyframe anchored = keyframe;  // as the Session does: the odometry's motion a weak anchor
      if (flight.factors.back().imu_factor) *anchored.relative_covariance *= VisualInertialFactorsConfig{}.odometry_covariance_scale;
      EXPECT_TRUE(graph->add_keyframe(anchored).ok());
      graph->add_factors(flight.factors.back().update);
      EXPECT_TRUE(graph->process().ok());
    }
  }
  return flight;
}

TEST(VisualInertialFactors, ImuAndLandmarkFactorsPutKeyframesBackOntoTheTruth) {
  VisualInertialFactors factors = make_factors();
  KeyframeGraphConfig config;
  config.smoother.background_batch = false;
  KeyframeGraph graph(config);
  const Flight flight = fly(factors, 6.0, &graph);
  ASSERT_EQ(flight.keyframes.size(), 12u);
  double initial_error = 0.0;
  for (size_t k = 0; k < flight.keyframes.size(); ++k) {
    EXPECT_EQ(flight.factors[k].imu_factor, k > 0) << "keyframe " << k;
    initial_error = std::max(initial_error, (flight.keyframes[k].T_world_body.to_se3().translation() - flight.truth[k].translation()).norm());
  }
  int landmarks = 0, projections = 0;
  for (const VisualInertialFactors::KeyframeFactors& made : flight.factors) {
    landmarks += made.new_landmarks;
    projections += made.projections;
  }
  EXPECT_GT(landmarks, 100);
  EXPECT_GT(projections, 3 * landmarks);
  ASSERT_TRUE(graph.smoother().wait_for_batch().ok());
  EXPECT_NEAR(initial_error, 0.1, 1e-9);
  // Keyframe to keyframe within 1 cm and 0.05 degrees (given 10-20 cm off); drift under 1 % of
  // the distance flown (visual-inertial odometry: yaw and position drift slowly).
  double distance = 0.0;
  for (size_t k = 1; k < flight.keyframes.size(); ++k) {
    const SE3 relative = graph.optimized_pose(k - 1).value().inverse() * graph.optimized_pose(k).value();
    const SE3 true_relative = flight.truth[k - 1].inverse() * flight.truth[k];
    EXPECT_LT((relative.translation() - true_relative.translation()).norm(), 0.01) << "keyframe " << k;
    EXPECT_LT((relative.rotation().inverse() * true_relative.rotation()).log().norm(), 0.05 * M_PI / 180.0) << "keyframe " << k;
    distance += true_relative.translation().norm();
    EXPECT_LT((graph.optimized_pose(k).value().translation() - flight.truth[k].translation()).norm(), 0.01 + 0.01 * distance) << "keyframe " << k;
    const Eigen::Vector3d velocity = graph.smoother().estimate().at<Eigen::Vector3d>(graph::V(k)).value();
    EXPECT_LT((velocity - true_velocity(flight.keyframes[k].timestamp.seconds() - 100.0)).norm(), 0.05) << "keyframe " << k;
  }
}

TEST(VisualInertialFactors, AnImuGapStartsANewChainWithPriors) {
  VisualInertialFactors factors = make_factors();
  const Flight flight = fly(factors, 4.0, nullptr, 1.2, 2.6);  // no IMU for 1.4 s: the keyframes at 1.505 and 2.005, 2.505 s
  ASSERT_EQ(flight.keyframes.size(), 8u);
  for (size_t k = 1; k < flight.keyframes.size(); ++k) {
    const double t = flight.keyframes[k].timestamp.seconds() - 100.0;
    // An interval the gap touches cannot be integrated (a sample held longer than 1 s).
    EXPECT_EQ(flight.factors[k].imu_factor, !(t > 1.2 && t < 3.1)) << "keyframe at " << t << " s";
    if (!flight.factors[k].imu_factor) {
      EXPECT_TRUE(flight.factors[k].update.values.exists(graph::V(k)));
      EXPECT_EQ(flight.factors[k].update.factors.size(), 2u + static_cast<size_t>(flight.factors[k].projections));  // two priors
    }
  }
}

TEST(VisualInertialFactors, TracksAcrossAnOdometryRestartAreNotTriangulatedTogether) {
  // The odometry's world jumps at 1.5 s: a landmark triangulated from views on both sides of the
  // jump would land metres off; none is made until its views are all after the restart.
  VisualInertialFactors factors = make_factors();
  const Flight flight = fly(factors, 3.0, nullptr, 1e9, 1e9, 1.5);
  ASSERT_EQ(flight.keyframes.size(), 6u);
  EXPECT_GT(flight.factors[2].new_landmarks, 0);   // 0.005 + 1.0 s: views at 0.5 and 1.0 s
  EXPECT_EQ(flight.factors[3].new_landmarks, 0);   // 1.505 s: its frame is the restart's
  EXPECT_GT(flight.factors[4].new_landmarks, 0);   // 2.005 s: views at 1.5 and 2.0 s
  for (size_t k = 3; k < flight.factors.size(); ++k) {
    for (const auto& [key, value] : flight.factors[k].update.values.all()) {
      if (graph::symbol_character(key) != 'l') continue;
      // Placed through a keyframe 10 cm / 1 degree off, triangulated over 0.75 m at 3-9 m.
      EXPECT_NEAR((std::get<Eigen::Vector3d>(value) - cylinder_points()[graph::symbol_index(key)]).norm(), 0.0, 1.0);
    }
  }
}

TEST(VisualInertialFactors, ObservationsOfLandmarksTheGraphPutsBehindTheCameraAreNotProjected) {
  // The graph's landmarks behind the camera that sees them (its estimates gone wrong): a factor
  // there could not be evaluated, so only the views that make a landmark get projections.
  VisualInertialFactors factors = make_factors();
  const Flight flight = fly(factors, 3.0, nullptr, 1e9, 1e9, 1e9, true);
  int projections = 0;
  for (const VisualInertialFactors::KeyframeFactors& made : flight.factors) {
    for (const graph::FactorPointer& factor : made.update.factors.factors()) {
      if (factor->dimension() != 2) continue;
      ++projections;
      EXPECT_TRUE(made.update.values.exists(factor->keys()[1])) << graph::key_to_string(factor->keys()[1]) << " is not a new landmark";
    }
  }
  EXPECT_GT(projections, 100);
}

}  // namespace
}  // namespace hanzo::fusion::pipeline
