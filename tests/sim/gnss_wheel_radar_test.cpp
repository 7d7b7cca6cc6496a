// GNSS, wheel odometry and radar simulators against the truth they are generated from.

#include <cmath>

#include <gtest/gtest.h>

#include "hanzo/fusion/msgs/validate.hpp"
#include "hanzo/fusion/sim/gnss_simulator.hpp"
#include "hanzo/fusion/sim/ground_path.hpp"
#include "hanzo/fusion/sim/radar_simulator.hpp"
#include "hanzo/fusion/sim/wheel_odometry_simulator.hpp"

namespace hanzo::fusion::sim {
namespace {

const Timestamp kStart = Timestamp::from_nanoseconds(1'700'000'000'000'000'000);

Timestamp at(double seconds) { return kStart + Duration::from_seconds(seconds); }

// A rectangular loop driven twice, with turns, starting and ending at rest.
SplineTrajectory loop_trajectory() {
  GroundPathConfig path;
  path.waypoints = {{0.0, 0.0, 0.2}, {20.0, 0.0, 0.2}, {20.0, 10.0, 0.2}, {-10.0, 10.0, 0.2}, {-10.0, 0.0, 0.2}};
  path.closed = true;
  path.laps = 2;
  path.max_speed = 3.0;
  return *make_ground_trajectory(kStart, path);
}

TEST(GroundPath, RespectsSpeedAndAccelerationLimitsAndStartsAtRest) {
  GroundPathConfig path;
  path.waypoints = {{0.0, 0.0, 0.0}, {30.0, 0.0, 0.0}, {30.0, 20.0, 0.0}, {0.0, 20.0, 0.0}};
  path.closed = true;
  path.max_speed = 5.0;
  path.max_acceleration = 1.0;
  path.max_lateral_acceleration = 2.0;
  path.corner_radius = 4.0;
  const SplineTrajectory trajectory = *make_ground_trajectory(kStart, path);
  const double duration = (trajectory.end_time() - kStart).seconds();
  // 100 m loop, 5 m/s at most: well over 20 s of driving plus the still periods.
  EXPECT_GT(duration, 24.0);
  double top_speed = 0.0;
  for (double t = 0.0; t <= duration; t += 0.01) {
    const TrajectorySample sample = trajectory.sample(at(t));
    const double speed = sample.velocity_world.norm();
    top_speed = std::max(top_speed, speed);
    ASSERT_LT(speed, 5.0 * 1.02) << t;
    ASSERT_LT(sample.acceleration_world.norm(), std::hypot(1.0, 2.0) * 1.3) << t;  // spline smoothing overshoot
    // A car does not slide sideways: velocity along the body x axis.
    if (speed > 0.5) {
      const Eigen::Vector3d velocity_body = sample.T_world_body.rotation().inverse() * sample.velocity_world;
      ASSERT_LT(std::abs(velocity_body.y()) / speed, 0.05) << t;
    }
  }
  EXPECT_GT(top_speed, 4.9);
  EXPECT_LT(trajectory.sample(at(1.0)).velocity_world.norm(), 1e-9);          // still start
  EXPECT_LT(trajectory.sample(trajectory.end_time()).velocity_world.norm(), 1e-9);
  EXPECT_LT((trajectory.sample(trajectory.end_time()).T_world_body.translation() - Eigen::Vector3d::Zero()).norm(), 1e-6);
  EXPECT_FALSE(make_ground_trajectory(kStart, GroundPathConfig{}));  // no waypoints
  GroundPathConfig u_turn = path;
  u_turn.closed = false;
  u_turn.waypoints = {{0.0, 0.0, 0.0}, {10.0, 0.0, 0.0}, {0.0, 0.1, 0.0}};
  const Result<SplineTrajectory> reversing = make_ground_trajectory(kStart, u_turn);
  ASSERT_FALSE(reversing);
  EXPECT_NE(reversing.error().message.find("waypoints[1]: turns 179 deg"), std::string::npos) << reversing.error().message;
  path.waypoints[1] = path.waypoints[0];
  EXPECT_FALSE(make_ground_trajectory(kStart, path));
}

TEST(GnssSimulator, FixesMatchTheTruthWithinTheConfiguredNoise) {
  const SplineTrajectory trajectory = loop_trajectory();
  GnssSimulatorConfig config;
  config.datum = {47.3769, 8.5417, 408.0};
  config.T_body_gnss = SE3(SO3(), {0.3, 0.0, 1.2});
  config.noise = Eigen::Vector2d(1.5, 3.0);
  Result<GnssSimulator> gnss = GnssSimulator::create(config, trajectory);
  ASSERT_TRUE(gnss);
  Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum_squares = Eigen::Vector3d::Zero();
  int count = 0;
  for (double t = 0.0; at(t) <= trajectory.end_time(); t += 0.1) {
    const msgs::GnssMessage fix = gnss->measure(at(t));
    ASSERT_TRUE(msgs::validate(fix));
    ASSERT_EQ(fix.fix_type, msgs::GnssFixType::kFix3d);
    ASSERT_TRUE(fix.position_covariance);
    EXPECT_NEAR((*fix.position_covariance)(0, 0), 2.25, 1e-12);
    // Converted back to ENU with an independent frame built from the same datum.
    const Eigen::Vector3d error = EnuFrame::create(config.datum)->to_enu(fix.geodetic()) - gnss->true_antenna_position(at(t));
    sum += error;
    sum_squares += error.cwiseProduct(error);
    ++count;
  }
  ASSERT_GT(count, 500);
  const Eigen::Vector3d mean = sum / count;
  const Eigen::Vector3d std_dev = (sum_squares / count - mean.cwiseProduct(mean)).cwiseSqrt();
  const Eigen::Vector3d sigma(1.5, 1.5, 3.0);
  for (int axis = 0; axis < 3; ++axis) {
    EXPECT_LT(std::abs(mean[axis]), 4.0 * sigma[axis] / std::sqrt(count)) << axis;
    EXPECT_NEAR(std_dev[axis] / sigma[axis], 1.0, 0.1) << axis;
  }
}

TEST(GnssSimulator, OutageReportsNoFixAndCanyonAddsMultipathJumps) {
  const SplineTrajectory trajectory = loop_trajectory();
  GnssSimulatorConfig config;
  config.datum = {47.3769, 8.5417, 408.0};
  config.fix_type = msgs::GnssFixType::kRtkFixed;
  GnssEpisode tunnel;
  tunnel.type = GnssEpisodeType::kOutage;
  tunnel.start = at(10.0);
  tunnel.end = at(15.0);
  GnssEpisode canyon;
  canyon.type = GnssEpisodeType::kDegraded;
  canyon.start = at(20.0);
  canyon.end = at(60.0);
  canyon.fix_type = msgs::GnssFixType::kFix3d;
  canyon.noise_scale = 1.0;
  canyon.multipath_rate_hz = 0.2;
  canyon.multipath_magnitude = 20.0;
  config.episodes = {tunnel, canyon};
  GnssSimulator gnss = *GnssSimulator::create(config, trajectory);
  const EnuFrame enu = *EnuFrame::create(config.datum);
  int no_fix = 0, jumps = 0, rtk = 0;
  for (int k = 0; k < 600; ++k) {
    const double t = 0.1 * k;
    const msgs::GnssMessage fix = gnss.measure(at(t));
    ASSERT_TRUE(msgs::validate(fix)) << t;
    const double error = (enu.to_enu(fix.geodetic()) - gnss.true_antenna_position(at(t))).head<2>().norm();
    if (k >= 100 && k <= 150) {
      EXPECT_EQ(fix.fix_type, msgs::GnssFixType::kNoFix);
      EXPECT_FALSE(fix.position_covariance);
      EXPECT_EQ(fix.satellites_used, 0U);
      ++no_fix;
    } else if (k < 200) {
      EXPECT_EQ(fix.fix_type, msgs::GnssFixType::kRtkFixed);
      EXPECT_LT(error, 0.02 * 6.0);  // 6 sigma of RTK
      ++rtk;
    } else {
      EXPECT_EQ(fix.fix_type, msgs::GnssFixType::kFix3d);
      if (error > 12.0) ++jumps;  // 8 sigma of FIX_3D: only a multipath jump gets there
    }
  }
  EXPECT_EQ(no_fix, 51);
  EXPECT_GT(rtk, 140);
  EXPECT_GT(jumps, 10);  // ~8 jumps of 3 s expected in 40 s: tens of affected fixes
}

TEST(GnssSimulator, BuildingsBlockSatellitesAndARoofLosesTheFix) {
  // The antenna drives east along y = 0 at 5 m/s: open sky, then an 8 m wide street between
  // two 30 m buildings (x 140..180), then through a 60 m underpass (x 200..260, deck 6-8 m up).
  std::vector<SE3> poses;
  for (int i = 0; i < 130; ++i) poses.emplace_back(SO3(), Eigen::Vector3d(5.0 * 0.5 * (i - 1), 0.0, 1.5));
  const SplineTrajectory trajectory = *SplineTrajectory::create(kStart, Duration::from_milliseconds(500), poses);
  WorldDescription description;
  Box building;
  building.half_size = {20.0, 10.0, 15.0};
  building.center = {160.0, 14.0, 15.0};
  description.boxes.push_back(building);
  building.center = {160.0, -14.0, 15.0};
  description.boxes.push_back(building);
  Box deck;
  deck.center = {230.0, 0.0, 7.0};
  deck.half_size = {30.0, 20.0, 1.0};
  description.boxes.push_back(deck);
  const World world(description);

  GnssSimulatorConfig config;
  config.datum = {47.3769, 8.5417, 408.0};
  config.fix_type = msgs::GnssFixType::kRtkFixed;
  config.sky_blockage = true;
  config.constellation = 12;
  ASSERT_FALSE(GnssSimulator::create(config, trajectory));  // sky blockage needs the world
  GnssSimulator gnss = *GnssSimulator::create(config, trajectory, &world);
  auto time_at_x = [](double x) { return at(x / 5.0); };
  EXPECT_EQ(gnss.visible_satellites(time_at_x(10.0)), 12);
  const int canyon_visible = gnss.visible_satellites(time_at_x(160.0));
  EXPECT_LT(canyon_visible, 6);  // 30 m walls 4 m away: only the sky along the street
  EXPECT_LT(gnss.visible_satellites(time_at_x(230.0)), 4);

  const msgs::GnssMessage open = gnss.measure(time_at_x(10.0));
  EXPECT_EQ(open.fix_type, msgs::GnssFixType::kRtkFixed);
  EXPECT_EQ(open.satellites_used, 14U);  // the configured count when nothing is blocked
  const msgs::GnssMessage canyon = gnss.measure(time_at_x(160.0));
  if (canyon_visible >= 4) {
    EXPECT_EQ(canyon.fix_type, msgs::GnssFixType::kFix3d);
    EXPECT_EQ(canyon.satellites_used, static_cast<uint32_t>(canyon_visible));
    EXPECT_GT((*canyon.position_covariance)(0, 0), 1.5 * 1.5);  // FIX_3D noise, scaled up
  } else {
    EXPECT_EQ(canyon.fix_type, msgs::GnssFixType::kNoFix);
  }
  const msgs::GnssMessage underpass = gnss.measure(time_at_x(230.0));
  EXPECT_EQ(underpass.fix_type, msgs::GnssFixType::kNoFix);
  EXPECT_FALSE(underpass.position_covariance);
  // Without sky blockage the same drive keeps its RTK fix everywhere.
  config.sky_blockage = false;
  GnssSimulator unblocked = *GnssSimulator::create(config, trajectory, &world);
  EXPECT_EQ(unblocked.measure(time_at_x(230.0)).fix_type, msgs::GnssFixType::kRtkFixed);
}

TEST(WheelOdometrySimulator, NoiselessDistancesDeadReckonTheTrajectory) {
  const SplineTrajectory trajectory = loop_trajectory();
  WheelOdometrySimulatorConfig config;
  config.distance_noise = 0.0;
  config.wheel_separation = 0.6;
  WheelOdometrySimulator wheels(config, trajectory);
  const SE3 start = trajectory.sample(kStart).T_world_body;
  double x = start.translation().x(), y = start.translation().y(), yaw = 0.0;
  msgs::WheelOdometryMessage previous = wheels.measure(kStart);
  const double duration = (trajectory.end_time() - kStart).seconds();
  for (double t = 0.02; t <= duration; t += 0.02) {
    const msgs::WheelOdometryMessage message = wheels.measure(at(t));
    ASSERT_TRUE(msgs::validate(message));
    const double left = message.left_distance - previous.left_distance, right = message.right_distance - previous.right_distance;
    const double forward = 0.5 * (left + right), turn = (right - left) / config.wheel_separation;
    x += forward * std::cos(yaw + 0.5 * turn);
    y += forward * std::sin(yaw + 0.5 * turn);
    yaw += turn;
    previous = message;
  }
  const SE3 end = trajectory.sample(at(duration)).T_world_body;
  // Two laps of 80 m each with eight corners: dead reckoning closes within a few centimetres.
  EXPECT_LT(std::hypot(x - end.translation().x(), y - end.translation().y()), 0.05);
  EXPECT_NEAR(std::remainder(yaw - end.rotation().log().z(), 2.0 * M_PI), 0.0, 1e-3);
  // Each of the 8 right-angle corners rounded with radius 2 m is 2 * (2 - pi / 2) shorter.
  EXPECT_NEAR(0.5 * (previous.left_distance + previous.right_distance), 2.0 * 80.0 - 8.0 * 2.0 * (2.0 - M_PI / 2.0), 0.05);
}

TEST(WheelOdometrySimulator, SlipScalesTheSlippingWheel) {
  const SplineTrajectory trajectory = loop_trajectory();
  WheelOdometrySimulatorConfig config;
  config.distance_noise = 0.0;
  config.slips.push_back({at(5.0), at(6.0), 1.5, 1.0});
  WheelOdometrySimulator wheels(config, trajectory);
  WheelOdometrySimulatorConfig clean_config = config;
  clean_config.slips.clear();
  WheelOdometrySimulator clean(clean_config, trajectory);
  msgs::WheelOdometryMessage slipping{}, truth{};
  double truth_left_before_slip = 0.0;
  for (int k = 0; k <= 300; ++k) {  // 0 .. 6 s every 20 ms
    slipping = wheels.measure(at(0.02 * k));
    truth = clean.measure(at(0.02 * k));
    if (k == 249) truth_left_before_slip = truth.left_distance;  // 4.98 s
  }
  // Increments ending inside [5, 6] s are 1.5 times the truth on the left wheel only.
  EXPECT_GT(truth.left_distance - truth_left_before_slip, 0.5);
  EXPECT_NEAR(slipping.left_distance - truth.left_distance, 0.5 * (truth.left_distance - truth_left_before_slip), 1e-9);
  EXPECT_DOUBLE_EQ(slipping.right_distance, truth.right_distance);
}

TEST(RadarSimulator, DopplerOfStaticAndMovingTargets) {
  // The radar drives at 3 m/s along +x past a pole, while a person walks towards it.
  std::vector<SE3> poses;
  for (int i = 0; i < 10; ++i) poses.emplace_back(SO3(), Eigen::Vector3d(3.0 * 0.5 * (i - 1), 0.0, 1.0));
  const SplineTrajectory trajectory = *SplineTrajectory::create(kStart, Duration::from_milliseconds(500), poses);
  WorldDescription description;
  Cylinder pole;
  pole.base_center = {20.0, 5.0, 0.0};
  pole.radius = 0.2;
  pole.height = 4.0;
  pole.material.radar_cross_section = 12.0;
  description.cylinders.push_back(pole);
  MovingBox person;
  person.box.half_size = {0.3, 0.3, 0.9};
  person.box.material.radar_cross_section = 0.0;
  person.path = {{30.0, -3.0}, {0.0, -3.0}};
  person.speed = 1.5;
  person.start_time = kStart;
  description.moving_boxes.push_back(person);
  const World world(description);
  RadarSimulatorConfig config;
  config.range_noise = config.azimuth_noise = config.elevation_noise = config.velocity_noise = config.rcs_noise = 0.0;
  config.clutter_rate = 0.0;
  RadarSimulator radar(config, world, trajectory);
  const msgs::RadarMessage scan = radar.measure(at(1.0));
  ASSERT_TRUE(msgs::validate(scan));
  ASSERT_EQ(scan.targets.size(), 2U);
  for (const msgs::RadarTarget& target : scan.targets) {
    const Eigen::Vector3d direction(std::cos(target.elevation) * std::cos(target.azimuth),
                                    std::cos(target.elevation) * std::sin(target.azimuth), std::sin(target.elevation));
    const Eigen::Vector3d target_position = Eigen::Vector3d(3.0, 0.0, 1.0) + target.range * direction;
    const bool is_pole = target.rcs > 6.0;
    const Eigen::Vector3d target_velocity = is_pole ? Eigen::Vector3d::Zero() : Eigen::Vector3d(-1.5, 0.0, 0.0);
    EXPECT_NEAR(target.radial_velocity, (target_velocity - Eigen::Vector3d(3.0, 0.0, 0.0)).dot(direction), 1e-4);
    if (is_pole) {
      EXPECT_NEAR(std::hypot(target_position.x() - 20.0, target_position.y() - 5.0), 0.2, 1e-3);
    } else {
      // On the surface of the person, who is at (28.5, -3) after walking 1 s.
      const Eigen::Vector2d local(target_position.x() - 28.5, target_position.y() + 3.0);
      EXPECT_NEAR(local.cwiseAbs().maxCoeff(), 0.3, 1e-3);
    }
  }
}

}  // namespace
}  // namespace hanzo::fusion::sim
