// Radar ego-velocity from Doppler: recovered from static targets despite moving ones, planar
// radars leave z unconstrained, too few targets are refused.

#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/estimate/radar_ego_velocity.hpp"

namespace hanzo::fusion::estimate {
namespace {

msgs::RadarTarget target(double azimuth, double elevation, const Eigen::Vector3d& sensor_velocity, const Eigen::Vector3d& target_velocity,
                         double noise) {
  const Eigen::Vector3d d(std::cos(elevation) * std::cos(azimuth), std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
  msgs::RadarTarget t;
  t.range = 20.0F;
  t.azimuth = static_cast<float>(azimuth);
  t.elevation = static_cast<float>(elevation);
  t.radial_velocity = static_cast<float>(d.dot(target_velocity - sensor_velocity) + noise);
  return t;
}

TEST(RadarEgoVelocity, RecoversTheSensorVelocityDespiteMovingTargets) {
  const Eigen::Vector3d velocity(8.0, -0.5, 0.2);
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> azimuth(-1.0, 1.0), elevation(-0.2, 0.2);
  std::normal_distribution<double> noise(0.0, 0.05);
  std::vector<msgs::RadarTarget> targets;
  for (int i = 0; i < 30; ++i) targets.push_back(target(azimuth(rng), elevation(rng), velocity, Eigen::Vector3d::Zero(), noise(rng)));
  for (int i = 0; i < 8; ++i) targets.push_back(target(azimuth(rng), elevation(rng), velocity, Eigen::Vector3d(-10.0, 3.0, 0.0), 0.0));
  const Result<RadarEgoVelocity> ego = estimate_radar_ego_velocity(targets);
  ASSERT_TRUE(ego.ok()) << ego.error().message;
  EXPECT_FALSE(ego->planar);
  EXPECT_EQ(ego->inliers, 30);
  EXPECT_LT((ego->velocity_sensor.head<2>() - velocity.head<2>()).norm(), 0.05);
  EXPECT_NEAR(ego->velocity_sensor.z(), velocity.z(), 0.3);
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_LT(std::abs(ego->velocity_sensor(axis) - velocity(axis)), 4.0 * std::sqrt(ego->covariance(axis, axis)) + 1e-3) << axis;
  }
}

TEST(RadarEgoVelocity, PlanarRadarLeavesZUnconstrainedAndTooFewTargetsFail) {
  const Eigen::Vector3d velocity(3.0, 0.0, 0.0);
  std::vector<msgs::RadarTarget> targets;
  for (int i = 0; i < 10; ++i) targets.push_back(target(-0.8 + 0.16 * i, 0.0, velocity, Eigen::Vector3d::Zero(), 0.0));
  const Result<RadarEgoVelocity> ego = estimate_radar_ego_velocity(targets);
  ASSERT_TRUE(ego.ok()) << ego.error().message;
  EXPECT_TRUE(ego->planar);
  EXPECT_NEAR(ego->velocity_sensor.x(), 3.0, 1e-4);
  EXPECT_GT(ego->covariance(2, 2), 100.0);
  targets.resize(3);
  const Result<RadarEgoVelocity> few = estimate_radar_ego_velocity(targets);
  ASSERT_FALSE(few.ok());
  EXPECT_NE(few.error().message.find("3 usable targets"), std::string::npos);
}

}  // namespace
}  // namespace hanzo::fusion::estimate
