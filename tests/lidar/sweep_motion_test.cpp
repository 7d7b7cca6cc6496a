// SweepMotion and deskew: a sensor that accelerates and turns faster during the sweep; the
// sampled motion puts every point where the sensor at the middle of the sweep would have seen it
// (to the sampling's interpolation error), the constant twist does not.

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "hanzo/fusion/lidar/sweep_motion.hpp"

namespace hanzo::fusion::lidar {
namespace {

// The sensor's pose in the world at time t (s): yaw rate 0.5 rad/s plus 8 rad/s^2 of angular
// acceleration, a rolling wobble, 3 m/s^2 forward acceleration.
SE3 T_world_sensor(double t) {
  const double yaw = 0.5 * t + 4.0 * t * t;
  const double roll = 0.02 * std::sin(20.0 * t);
  const Eigen::Matrix3d rotation =
      (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX())).toRotationMatrix();
  return SE3(SO3::from_matrix(rotation), Eigen::Vector3d(2.0 * t + 1.5 * t * t, 0.5 * t, 0.0));
}

struct SkewedSweep {
  cloud::PointCloud scan;                    // sensor frame at each point's time
  std::vector<Eigen::Vector3f> at_middle;    // the same points in the sensor frame at the middle
};

// 0.1 s sweep, 360 firing columns of 16 points on walls 8-20 m away.
SkewedSweep skewed_sweep() {
  SkewedSweep sweep;
  const SE3 T_middle_world = T_world_sensor(0.05).inverse();
  for (int column = 0; column < 360; ++column) {
    const double t = 0.1 * column / 360.0;
    const SE3 T_sensor_world = T_world_sensor(t).inverse();
    const double azimuth = 2.0 * M_PI * column / 360.0;
    for (int ring = 0; ring < 16; ++ring) {
      const double range = 8.0 + 12.0 * ((column * 7 + ring * 3) % 17) / 16.0;
      const double elevation = -0.26 + 0.035 * ring;
      const Eigen::Vector3d world = T_world_sensor(t) * (range * Eigen::Vector3d(std::cos(elevation) * std::cos(azimuth),
                                                                                  std::cos(elevation) * std::sin(azimuth),
                                                                                  std::sin(elevation)));
      sweep.scan.positions.push_back((T_sensor_world * world).cast<float>());
      sweep.scan.times.push_back(static_cast<float>(t));
      sweep.at_middle.push_back((T_middle_world * world).cast<float>());
    }
  }
  return sweep;
}

double worst_error(const cloud::PointCloud& deskewed, const std::vector<Eigen::Vector3f>& expected) {
  double worst = 0.0;
  for (std::size_t i = 0; i < expected.size(); ++i) worst = std::max(worst, static_cast<double>((deskewed.positions[i] - expected[i]).norm()));
  return worst;
}

SweepMotion sampled_motion(double interval) {
  const SE3 T_middle_world = T_world_sensor(0.05).inverse();
  std::vector<double> times;
  std::vector<SE3> poses;
  for (double t = 0.0; t <= 0.1 + 1e-12; t += interval) {
    times.push_back(t);
    poses.push_back(T_middle_world * T_world_sensor(t));
  }
  return SweepMotion::from_samples(times, poses).value();
}

TEST(SweepMotion, SampledMotionDeskewsAnAcceleratingTurnToMillimetres) {
  const SkewedSweep sweep = skewed_sweep();
  const double skew = worst_error(sweep.scan, sweep.at_middle);
  EXPECT_GT(skew, 0.5);  // not deskewed: half a metre off at the sweep's ends

  cloud::PointCloud sampled = sweep.scan;
  deskew(sampled, sampled_motion(0.005));  // an IMU at 200 Hz
  const double sampled_error = worst_error(sampled, sweep.at_middle);
  EXPECT_LT(sampled_error, 2e-3);

  // The constant-velocity model: the twist between the previous sweep's middle and this one's.
  const SE3::Tangent twist = (T_world_sensor(-0.05).inverse() * T_world_sensor(0.05)).log() / 0.1;
  cloud::PointCloud constant = sweep.scan;
  deskew(constant, SweepMotion::constant_twist(twist, 0.05));
  const double constant_error = worst_error(constant, sweep.at_middle);
  EXPECT_GT(constant_error, 0.05);
  EXPECT_LT(constant_error, skew);
  EXPECT_GT(constant_error, 50.0 * sampled_error);
}

TEST(SweepMotion, InterpolatesOnTheGeodesicAndExtrapolatesTheEndSegments) {
  const SE3 a = SE3::exp((SE3::Tangent() << 0.1, 0.2, 0.0, 0.0, 0.0, 0.3).finished());
  const SE3 b = SE3::exp((SE3::Tangent() << 0.5, 0.1, 0.1, 0.02, 0.0, 0.5).finished());
  const SE3 c = SE3::exp((SE3::Tangent() << 0.9, 0.0, 0.1, 0.0, 0.05, 0.6).finished());
  const SweepMotion motion = SweepMotion::from_samples({0.0, 0.04, 0.1}, {a, b, c}).value();
  EXPECT_EQ(motion.segments(), 2U);
  EXPECT_FALSE(motion.is_identity());
  EXPECT_LT((motion.at(0.0).log() - a.log()).norm(), 1e-12);
  EXPECT_LT((motion.at(0.04).log() - b.log()).norm(), 1e-12);
  EXPECT_LT((motion.at(0.1).log() - c.log()).norm(), 1e-12);
  EXPECT_LT((motion.at(0.02).log() - SE3::interpolate(a, b, 0.5).log()).norm(), 1e-12);
  EXPECT_LT((motion.at(0.07).log() - SE3::interpolate(b, c, 0.5).log()).norm(), 1e-12);
  // Beyond the ends: the end segment's twist continues.
  EXPECT_LT((motion.at(-0.04).log() - (a * (b.inverse() * a)).log()).norm(), 1e-12);
  EXPECT_LT((motion.at(0.16).log() - (c * (b.inverse() * c)).log()).norm(), 1e-12);
}

TEST(SweepMotion, ConstantTwistAndIdentity) {
  const SE3::Tangent twist = (SE3::Tangent() << 1.0, 0.0, 0.0, 0.0, 0.0, 2.0).finished();
  const SweepMotion motion = SweepMotion::constant_twist(twist, 0.05);
  EXPECT_LT(motion.at(0.05).log().norm(), 1e-15);
  EXPECT_LT((motion.at(0.0).log() - (-0.05 * twist)).norm(), 1e-12);
  EXPECT_TRUE(SweepMotion().is_identity());
  EXPECT_TRUE(SweepMotion::constant_twist(SE3::Tangent::Zero(), 0.05).is_identity());

  // Nothing to do: no motion, or no per-point times.
  const SkewedSweep sweep = skewed_sweep();
  cloud::PointCloud unchanged = sweep.scan;
  deskew(unchanged, SweepMotion());
  EXPECT_EQ(unchanged.positions, sweep.scan.positions);
  unchanged.times.clear();
  deskew(unchanged, motion);
  EXPECT_EQ(unchanged.positions, sweep.scan.positions);
}

TEST(SweepMotion, RejectsBadSamples) {
  const SE3 pose;
  auto sizes = SweepMotion::from_samples({0.0, 0.1}, {pose});
  ASSERT_FALSE(sizes.ok());
  EXPECT_NE(sizes.error().message.find("2 times but 1 poses"), std::string::npos);
  EXPECT_FALSE(SweepMotion::from_samples({0.0}, {pose}).ok());
  auto repeated = SweepMotion::from_samples({0.0, 0.05, 0.05}, {pose, pose, pose});
  ASSERT_FALSE(repeated.ok());
  EXPECT_NE(repeated.error().message.find("sample 2"), std::string::npos);
  auto nan = SweepMotion::from_samples({0.0, std::numeric_limits<double>::quiet_NaN()}, {pose, pose});
  ASSERT_FALSE(nan.ok());
  EXPECT_NE(nan.error().message.find("not finite"), std::string::npos);
  Eigen::Matrix4d bad = Eigen::Matrix4d::Identity();
  bad(0, 3) = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(SweepMotion::from_samples({0.0, 0.1}, {pose, SE3::from_matrix(bad)}).ok());
}

}  // namespace
}  // namespace hanzo::fusion::lidar
