// In-motion alignment on a synthetic car: a turn at changing speed, forwards and in reverse,
// and the inputs it refuses.
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "hanzo/fusion/estimate/attitude_models.hpp"
#include "hanzo/fusion/estimate/in_motion_alignment.hpp"
#include "hanzo/fusion/estimate/static_alignment.hpp"

namespace hanzo::fusion::estimate {
namespace {

constexpr double kGravity = 9.81;

// A level car on a circle: heading psi0 + w t, speed v0 + a t along it (backwards when
// reversing), GNSS at 10 Hz with `noise` m, IMU at 100 Hz, for `seconds`.
InMotionAlignmentInput turning_car(double psi0, double w, double v0, double a, bool reversing, double noise, double seconds) {
  std::mt19937 rng(3);
  std::normal_distribution<double> normal(0.0, noise);
  InMotionAlignmentInput input;
  input.reversing = reversing;
  input.gravity_magnitude = kGravity;
  const Timestamp start = Timestamp::from_seconds(100.0);
  Eigen::Vector2d position = Eigen::Vector2d::Zero();
  const double dt = 0.001;
  for (int step = 0; step <= static_cast<int>(seconds / dt); ++step) {
    const double t = step * dt;
    const double heading = psi0 + w * t;
    const double speed = v0 + a * t;                     // along the body x axis (negative: reversing)
    const double signed_speed = reversing ? -speed : speed;
    const Eigen::Vector2d forward(std::cos(heading), std::sin(heading));
    if (step % 100 == 0) {
      input.fixes.push_back({start + Duration::from_seconds(t), Eigen::Vector3d(position.x() + normal(rng), position.y() + normal(rng), 0.0),
                             std::max(noise, 0.01)});
    }
    if (step % 10 == 0) {
      // Body frame: forward acceleration d(signed speed)/dt, lateral w x v; specific force a - g.
      const Eigen::Vector3d acceleration_body((reversing ? -a : a), w * signed_speed, 0.0);
      input.imu.push_back({start + Duration::from_seconds(t), Eigen::Vector3d(0.0, 0.0, w), acceleration_body + Eigen::Vector3d(0, 0, kGravity)});
    }
    position += signed_speed * forward * dt;
  }
  input.now = input.fixes.back().time;
  return input;
}

double heading_error(const InMotionAlignment& alignment, double truth) {
  return std::remainder(roll_pitch_yaw(alignment.R_world_body.matrix()).z() - truth, 2.0 * M_PI);
}

TEST(InMotionAlignment, RecoversHeadingVelocityAndLevelInATurn) {
  // 4 s of a 0.2 rad/s turn while accelerating from 8 m/s at 1 m/s^2, 5 cm GNSS noise.
  const InMotionAlignmentInput input = turning_car(1.0, 0.2, 8.0, 1.0, false, 0.05, 4.0);
  const Result<InMotionAlignment> alignment = align_in_motion(input);
  ASSERT_TRUE(alignment) << alignment.error().message;
  // The quadratic fit of a 0.8 rad arc is off by about a degree and 1 % of the speed.
  const double heading_now = 1.0 + 0.2 * 4.0, speed_now = 12.0;
  EXPECT_NEAR(heading_error(*alignment, heading_now), 0.0, 0.02);
  EXPECT_NEAR(alignment->velocity.head<2>().norm(), speed_now, 0.2);
  EXPECT_LT((alignment->velocity.head<2>().normalized() - Eigen::Vector2d(std::cos(heading_now), std::sin(heading_now))).norm(), 0.02);
  // Level: the centripetal (2.4 m/s^2) and forward (1 m/s^2) accelerations compensated.
  const Eigen::Vector3d rpy = roll_pitch_yaw(alignment->R_world_body.matrix());
  EXPECT_NEAR(rpy.x(), 0.0, 0.01);
  EXPECT_NEAR(rpy.y(), 0.0, 0.01);
  EXPECT_GT(alignment->orientation_sigma.z(), 0.0);

  // The same with the forward acceleration measured (wheels) and 2.5 m noise over the window.
  InMotionAlignmentInput noisy = turning_car(-2.0, 0.05, 12.0, 0.5, false, 2.5, 4.0);
  noisy.forward_acceleration = std::make_pair(0.5, 0.05);
  const Result<InMotionAlignment> rough = align_in_motion(noisy);
  ASSERT_TRUE(rough) << rough.error().message;
  EXPECT_NEAR(heading_error(*rough, -2.0 + 0.05 * 4.0), 0.0, 3.0 * rough->orientation_sigma.z());
  EXPECT_NEAR(roll_pitch_yaw(rough->R_world_body.matrix()).y(), 0.0, 0.01);
}

TEST(InMotionAlignment, ReversingFacesAgainstTheCourse) {
  const InMotionAlignmentInput input = turning_car(0.5, -0.1, 3.0, 0.0, true, 0.05, 3.0);
  const Result<InMotionAlignment> alignment = align_in_motion(input);
  ASSERT_TRUE(alignment) << alignment.error().message;
  EXPECT_NEAR(heading_error(*alignment, 0.5 - 0.1 * 3.0), 0.0, 0.01);
  EXPECT_NEAR(roll_pitch_yaw(alignment->R_world_body.matrix()).x(), 0.0, 0.01);
}

TEST(InMotionAlignment, RefusesWhatCannotGiveAHeading) {
  const InMotionAlignmentInput slow = turning_car(0.0, 0.0, 0.5, 0.0, false, 0.05, 3.0);
  const auto too_slow = align_in_motion(slow);
  ASSERT_FALSE(too_slow);
  EXPECT_NE(too_slow.error().message.find("too low for a course"), std::string::npos);

  InMotionAlignmentInput few = turning_car(0.0, 0.0, 10.0, 0.0, false, 0.05, 3.0);
  few.fixes.resize(2);
  few.now = few.fixes.back().time;
  EXPECT_NE(align_in_motion(few).error().message.find("needs 3"), std::string::npos);

  InMotionAlignmentInput blind = turning_car(0.0, 0.0, 10.0, 0.0, false, 0.05, 3.0);
  blind.imu.clear();
  EXPECT_NE(align_in_motion(blind).error().message.find("no IMU sample"), std::string::npos);

  // A noisy short track waits for more fixes (the course would be noise).
  const InMotionAlignmentInput noisy = turning_car(0.0, 0.0, 4.0, 0.0, false, 2.5, 1.5);
  EXPECT_FALSE(align_in_motion(noisy));
}

TEST(InMotionAlignment, RollAndPitchFromAnySpecificForce) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> angle(-0.4, 0.4), yaw(-M_PI, M_PI), acceleration(-3.0, 3.0);
  for (int i = 0; i < 100; ++i) {
    const double roll = angle(rng), pitch = angle(rng), heading = yaw(rng);
    const SO3 R = rotation_from_roll_pitch_yaw(roll, pitch, heading);
    const Eigen::Vector3d f_world(acceleration(rng), acceleration(rng), kGravity + acceleration(rng) / 3.0);
    const Eigen::Vector2d found = roll_pitch_from_specific_force(R.inverse() * f_world, f_world, heading);
    EXPECT_NEAR(found.x(), roll, 1e-9);
    EXPECT_NEAR(found.y(), pitch, 1e-9);
  }
}

}  // namespace
}  // namespace hanzo::fusion::estimate
