// Scan-to-map registration on surfaces (exact simulated poses, corridor degeneracy, bad input)
// and LiDAR odometry on the simulated warehouse_robot (VLP-16 indoors) and urban_vehicle
// (OS1-64 in a city, with a rain episode) scenarios against their ground truth.

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include <gtest/gtest.h>

#include "hanzo/fusion/cloud/scan_normals.hpp"
#include "hanzo/fusion/eval/kitti_odometry.hpp"
#include "hanzo/fusion/lidar/lidar_odometry.hpp"
#include "hanzo/fusion/lidar/surface_registration.hpp"
#include "hanzo/fusion/sim/scenario.hpp"
#include "hanzo/fusion/sim/scenario_simulation.hpp"
#include "simulated_scan.hpp"

namespace hanzo::fusion::lidar {
namespace {

double rotation_error_deg(const SE3& a, const SE3& b) { return (a.rotation().inverse() * b.rotation()).log().norm() * 180.0 / M_PI; }

SE3 pose(double x, double y, double z, double yaw_deg) {
  return SE3(SO3::exp(Eigen::Vector3d(0, 0, yaw_deg * M_PI / 180.0)), Eigen::Vector3d(x, y, z));
}

// A map of `world` from scans taken at `poses` (points with their range-image normals).
cloud::VoxelHashMap map_of(const sim::World& world, const std::vector<SE3>& poses) {
  cloud::VoxelHashMap map({.voxel_size = 1.0, .max_points_per_voxel = 20, .min_point_spacing = -1.0, .max_distance = 100.0});
  uint32_t seed = 10;
  for (const SE3& T_world_sensor : poses) {
    const cloud::PointCloud scan = testing_support::scan(world, T_world_sensor, 0.01, seed++);
    const std::vector<Eigen::Vector3f> normals = cloud::estimate_scan_normals(scan);
    std::vector<Eigen::Vector3f> points, world_normals;
    for (std::size_t i = 0; i < scan.size(); ++i) {
      points.push_back((T_world_sensor * scan.positions[i].cast<double>()).cast<float>());
      world_normals.push_back((T_world_sensor.rotation().matrix() * normals[i].cast<double>()).cast<float>());
    }
    map.add(points, world_normals, T_world_sensor.translation());
  }
  return map;
}

std::vector<Eigen::Vector3f> source_points(const sim::World& world, const SE3& T_world_sensor) {
  const cloud::PointCloud scan = testing_support::scan(world, T_world_sensor, 0.01, 99);
  std::vector<Eigen::Vector3f> points;
  for (std::size_t i = 0; i < scan.size(); i += 7) points.push_back(scan.positions[i]);
  return points;
}

TEST(SurfaceRegistration, RecoversTheTruePoseInTheYardToOneCentimetre) {
  const sim::World world = testing_support::registration_world();
  const cloud::VoxelHashMap map = map_of(world, {pose(0, 0, 1.8, 0), pose(1.0, 0.5, 1.8, 10)});
  const SE3 truth = pose(0.8, -0.6, 1.8, 25);
  const std::vector<Eigen::Vector3f> source = source_points(world, truth);
  for (const SE3& offset : {pose(0.3, -0.2, 0.05, 3), pose(-0.25, 0.3, -0.05, -4)}) {
    const SE3 guess = truth * offset;
    auto result = align_to_surfaces(source, map, guess, guess);
    ASSERT_TRUE(result.ok()) << result.error().message;
    EXPECT_LT((result->T_map_source.translation() - truth.translation()).norm(), 0.01);
    EXPECT_LT(rotation_error_deg(result->T_map_source, truth), 0.05);
    EXPECT_TRUE(result->converged);
    EXPECT_GT(result->plane_correspondences, source.size() / 2);
    EXPECT_GT(translation_constraint_ratio(result->information), 0.02);
  }
}

// A sweep deskewed with the wrong twist (a turn onset: 0.3 rad/s and 0.4 m/s off): with the
// deskew coupled to the estimate, the registration finds both the pose and the twist; with the
// deskew as given, it settles on a pose that suits the warped sweep.
TEST(SurfaceRegistration, CoupledDeskewFindsTheSweepsOwnMotion) {
  const sim::World world = testing_support::registration_world();
  const cloud::VoxelHashMap map = map_of(world, {pose(0, 0, 1.8, 0), pose(1.0, 0.5, 1.8, 10)});
  const SE3 truth = pose(0.8, -0.6, 1.8, 25);
  const std::vector<Eigen::Vector3f> at_middle = source_points(world, truth);  // deskewed with the true twist
  SE3::Tangent twist_error;
  twist_error << 0.4, 0.1, 0.0, 0.0, 0.0, 0.3;  // true twist - the twist the sweep was deskewed with, per second
  DeskewCoupling coupling{.times = {}, .translation_gain = 15.0, .rotation_gain = 15.0};  // 1.5 / 0.1 s
  std::vector<Eigen::Vector3f> source;
  for (const Eigen::Vector3f& p : at_middle) {
    const float time = 0.05F * std::atan2(p.y(), p.x()) / static_cast<float>(M_PI);  // one turn in 0.1 s about the middle
    coupling.times.push_back(time);
    source.push_back((SE3::exp(-static_cast<double>(time) * twist_error) * p.cast<double>()).cast<float>());
  }
  // The prediction the wrong twist came from: the estimate's offset from it implies the twist error.
  const SE3 prediction = truth * SE3::exp(-twist_error / 15.0);
  auto coupled = align_to_surfaces(source, map, prediction, prediction, {}, &coupling);
  ASSERT_TRUE(coupled.ok()) << coupled.error().message;
  auto fixed = align_to_surfaces(source, map, prediction, prediction);
  ASSERT_TRUE(fixed.ok()) << fixed.error().message;
  const double coupled_error = (coupled->T_map_source.translation() - truth.translation()).norm();
  const double fixed_error = (fixed->T_map_source.translation() - truth.translation()).norm();
  // Measured: coupled 1.1 mm, 0.016 deg; fixed 14 mm, 0.041 deg.
  EXPECT_LT(coupled_error, 0.005);
  EXPECT_LT(rotation_error_deg(coupled->T_map_source, truth), 0.05);
  EXPECT_TRUE(coupled->converged);
  EXPECT_GT(fixed_error, 3.0 * coupled_error);
}

// A poor guess (0.5 m, 8 deg off) takes its large steps on every fourth point, then all points
// finish to the same centimetre as registering all points throughout; when the subset matches
// too few surfaces, all points are used from the start.
TEST(SurfaceRegistration, CoarseSubsetTakesTheLargeStepsAndAllPointsTheLast) {
  const sim::World world = testing_support::registration_world();
  const cloud::VoxelHashMap map = map_of(world, {pose(0, 0, 1.8, 0), pose(1.0, 0.5, 1.8, 10)});
  const SE3 truth = pose(0.8, -0.6, 1.8, 25);
  const cloud::PointCloud scan = testing_support::scan(world, truth, 0.01, 99);
  std::vector<Eigen::Vector3f> source;
  for (std::size_t i = 0; i < scan.size(); i += 2) source.push_back(scan.positions[i]);
  ASSERT_GT(source.size(), 4000u);  // a subset of more than 1000 points
  const SE3 guess = truth * pose(0.4, -0.3, 0.05, 8);
  for (const std::size_t stride : {1u, 4u}) {
    SurfaceRegistrationConfig config;
    config.coarse_stride = stride;
    auto result = align_to_surfaces(source, map, guess, guess, config);
    ASSERT_TRUE(result.ok()) << result.error().message;
    EXPECT_LT((result->T_map_source.translation() - truth.translation()).norm(), 0.01) << stride;
    EXPECT_LT(rotation_error_deg(result->T_map_source, truth), 0.05) << stride;
    EXPECT_TRUE(result->converged);
    if (stride == 1) {
      EXPECT_EQ(result->coarse_iterations, 0);
    } else {
      EXPECT_GE(result->coarse_iterations, 2);
    }
    EXPECT_GT(result->correspondences, source.size() / 2);  // the last iterations saw every point
  }
  SurfaceRegistrationConfig narrow;  // the kernel starts at its final width: no coarse phase
  narrow.initial_kernel_width = narrow.kernel_width;
  auto narrow_result = align_to_surfaces(source, map, truth * pose(0.05, -0.03, 0.0, 1), truth * pose(0.05, -0.03, 0.0, 1), narrow);
  ASSERT_TRUE(narrow_result.ok()) << narrow_result.error().message;
  EXPECT_EQ(narrow_result->coarse_iterations, 0);
  EXPECT_GT(narrow_result->correspondences, source.size() / 2);
  SurfaceRegistrationConfig demanding;
  demanding.min_correspondences = source.size() / 2;  // more than a quarter of the points match
  auto result = align_to_surfaces(source, map, guess, guess, demanding);
  ASSERT_TRUE(result.ok()) << result.error().message;
  EXPECT_EQ(result->coarse_iterations, 0);
  EXPECT_LT((result->T_map_source.translation() - truth.translation()).norm(), 0.01);
}

TEST(SurfaceRegistration, BareCorridorIsDegenerateAndKeepsThePriorAlongItsAxis) {
  sim::WorldDescription corridor;
  for (const double y : {2.0, -2.0}) {
    sim::Box wall;
    wall.center = {0, y, 2};
    wall.half_size = {200, 0.2, 2};
    corridor.boxes.push_back(wall);
  }
  const sim::World world(corridor);
  const cloud::VoxelHashMap map = map_of(world, {pose(0, 0, 1.0, 0), pose(0.5, 0, 1.0, 0)});
  const SE3 truth = pose(0.3, 0.1, 1.0, 2);
  const std::vector<Eigen::Vector3f> source = source_points(world, truth);
  const SE3 guess = truth * pose(0.4, -0.1, 0.0, 1);  // 0.4 m too far along the corridor
  auto result = align_to_surfaces(source, map, guess, guess);
  ASSERT_TRUE(result.ok()) << result.error().message;
  EXPECT_LT(translation_constraint_ratio(result->information), 0.02);
  // Across the corridor, height, rotation: recovered. Along it: the prior's value stays.
  EXPECT_NEAR(result->T_map_source.translation().y(), truth.translation().y(), 0.02);
  EXPECT_NEAR(result->T_map_source.translation().z(), truth.translation().z(), 0.02);
  EXPECT_LT(rotation_error_deg(result->T_map_source, truth), 0.1);
  // (within 0.1 m of the prior, the truth being 0.4 m away: the 1 cm range noise tilts the
  // estimated wall normals a little along the axis, which adds a weak, noisy constraint there;
  // measured 6-9 cm depending on which points share a range-image column)
  EXPECT_NEAR(result->T_map_source.translation().x(), guess.translation().x(), 0.1);
  EXPECT_GT(std::abs(result->T_map_source.translation().x() - truth.translation().x()), 0.3);
}

TEST(SurfaceRegistration, RefusesBadInput) {
  const sim::World world = testing_support::registration_world();
  const cloud::VoxelHashMap map = map_of(world, {pose(0, 0, 1.8, 0)});
  const std::vector<Eigen::Vector3f> source = source_points(world, pose(0, 0, 1.8, 0));
  auto empty = align_to_surfaces({}, map, SE3(), SE3());
  ASSERT_FALSE(empty.ok());
  EXPECT_NE(empty.error().message.find("no points"), std::string::npos);
  auto far = align_to_surfaces(source, map, pose(500, 0, 0, 0), pose(500, 0, 0, 0));
  ASSERT_FALSE(far.ok());
  EXPECT_NE(far.error().message.find("does not overlap"), std::string::npos);
  SurfaceRegistrationConfig config;
  config.kernel_width = -1.0;
  auto invalid = align_to_surfaces(source, map, SE3(), SE3(), config);
  ASSERT_FALSE(invalid.ok());
  EXPECT_NE(invalid.error().message.find("kernel_width"), std::string::npos);
  config = {};
  config.coarse_stride = 0;
  auto no_stride = align_to_surfaces(source, map, SE3(), SE3(), config);
  ASSERT_FALSE(no_stride.ok());
  EXPECT_NE(no_stride.error().message.find("coarse_stride"), std::string::npos);
  DeskewCoupling coupling{.times = std::vector<float>(source.size() - 1, 0.0F), .translation_gain = 0.0, .rotation_gain = 15.0};
  auto miscounted = align_to_surfaces(source, map, SE3(), SE3(), {}, &coupling);
  ASSERT_FALSE(miscounted.ok());
  EXPECT_NE(miscounted.error().message.find("deskew times"), std::string::npos);
  coupling.times.assign(source.size(), 0.0F);
  coupling.times[7] = -0.1F;  // 1 + 15 * -0.1 < 0: the point would move against the pose
  auto reversed = align_to_surfaces(source, map, SE3(), SE3(), {}, &coupling);
  ASSERT_FALSE(reversed.ok());
  EXPECT_NE(reversed.error().message.find("point 7"), std::string::npos);
  coupling.times[7] = 0.0F;
  coupling.translation_gain = std::numeric_limits<double>::quiet_NaN();
  auto not_finite = align_to_surfaces(source, map, SE3(), SE3(), {}, &coupling);
  ASSERT_FALSE(not_finite.ok());
  EXPECT_NE(not_finite.error().message.find("gain"), std::string::npos);
}

// Runs LiDAR odometry over a scenario's LiDAR sweeps (the other sensors left out), starting at
// the true pose, and returns the body trajectories (truth, estimate) at the estimates' times.
struct OdometryRun {
  io::Trajectory truth;
  io::Trajectory estimate;
  std::size_t scans = 0;
  std::size_t degenerate = 0;
  std::size_t weather_in_rain = 0;     // sweeps flagged weather_degraded inside the rain episode
  std::size_t weather_outside = 0;     // and outside it
  std::size_t phantoms_outside = 0;    // lone near returns dropped outside it
  double path_m = 0.0;
};

OdometryRun run_scenario(const std::string& path, double duration_s, LidarOdometryConfig config,
                         std::optional<sim::LidarModel> model = std::nullopt) {
  sim::Scenario scenario = sim::load_scenario(path).value();
  std::erase_if(scenario.sensors, [](const sim::ScenarioSensor& s) { return s.modality != config::SensorModality::kLidar; });
  if (model) std::get<sim::LidarSimulatorConfig>(scenario.sensors.front().simulator).pattern = sim::LidarPattern::preset(*model);
  scenario.duration = duration_s;
  scenario.num_threads = 0;
  auto simulation = sim::ScenarioSimulation::create(scenario).value();
  const SE3 T_body_lidar = scenario.sensors.front().T_body_sensor;
  const std::vector<sim::LidarWeatherEpisode>& weather = std::get<sim::LidarSimulatorConfig>(scenario.sensors.front().simulator).weather;
  const sim::SplineTrajectory& trajectory = simulation->trajectory();
  std::unique_ptr<LidarOdometry> odometry;
  OdometryRun run;
  const Status status = simulation->run([&](const sim::ScenarioSensor&, msgs::SensorMessage&& message) -> Status {
    const auto& sweep = std::get<msgs::PointCloudMessage>(message);
    cloud::PointCloud scan;
    HANZO_ASSIGN_OR_RETURN(scan, cloud::from_message(sweep));
    if (!odometry) {
      const double middle = 0.5 * static_cast<double>(*std::max_element(scan.times.begin(), scan.times.end()));
      const SE3 start = trajectory.sample(sweep.timestamp + Duration::from_seconds(middle)).T_world_body * T_body_lidar;
      odometry = std::make_unique<LidarOdometry>(config, start);
    }
    auto estimate = odometry->add_scan(sweep.timestamp, scan);
    if (!estimate) return estimate.error();
    ++run.scans;
    run.degenerate += estimate->degenerate ? 1 : 0;
    const bool raining = std::any_of(weather.begin(), weather.end(), [&](const sim::LidarWeatherEpisode& e) {
      return sweep.timestamp + Duration::from_seconds(0.1) >= e.start && sweep.timestamp <= e.end;
    });
    (raining ? run.weather_in_rain : run.weather_outside) += estimate->weather_degraded ? 1 : 0;
    if (!raining) run.phantoms_outside += estimate->phantom_points;
    run.truth.timestamps.push_back(estimate->time);
    run.truth.poses.push_back(trajectory.sample(estimate->time).T_world_body.matrix());
    run.estimate.timestamps.push_back(estimate->time);
    run.estimate.poses.push_back((estimate->T_world_lidar * T_body_lidar.inverse()).matrix());
    return ok_status();
  });
  EXPECT_TRUE(status.ok()) << status.error().message;
  run.path_m = run.truth.path_length();
  return run;
}

double final_error(const OdometryRun& run) {
  return (run.truth.position(run.truth.size() - 1) - run.estimate.position(run.estimate.size() - 1)).norm();
}

double rmse(const OdometryRun& run) {
  double sum = 0.0;
  for (std::size_t i = 0; i < run.truth.size(); ++i) sum += (run.truth.position(i) - run.estimate.position(i)).squaredNorm();
  return std::sqrt(sum / static_cast<double>(run.truth.size()));
}

TEST(LidarOdometry, WarehouseRobotVlp16StaysWithinCentimetres) {
  LidarOdometryConfig config;
  config.source_voxel_size = 0.25;  // indoors
  const OdometryRun run = run_scenario("examples/scenarios/warehouse_robot.yaml", 40.0, config);
  ASSERT_GT(run.scans, 350U);
  EXPECT_GT(run.path_m, 40.0);
  EXPECT_EQ(run.degenerate, 0U);
  EXPECT_LT(rmse(run), 0.1) << "path " << run.path_m << " m";
  EXPECT_LT(final_error(run), 0.005 * run.path_m);
}

TEST(LidarOdometry, HandheldSwingsAreDeskewedWithTheMotionTheRegistrationFinds) {
  // A handheld VLP-16 swung +-0.9 rad every 2.5 s while walking the warehouse, LiDAR only, with
  // indoor map voxels: the turn rate changes by up to 0.6 rad/s within a sweep, so the constant
  // twist of the previous motion deskews it wrongly and the map fills with warped sweeps unless
  // the deskew follows the registration (deskew_coupling).
  LidarOdometryConfig config;
  config.map.voxel_size = 0.5;
  config.registration.max_neighbour_distance = 0.5;
  config.source_voxel_size = 0.25;
  const OdometryRun coupled = run_scenario("examples/scenarios/handheld_lidar.yaml", 20.0, config);
  config.deskew_rotation_coupling = 0.0;
  const OdometryRun predicted = run_scenario("examples/scenarios/handheld_lidar.yaml", 20.0, config);
  ASSERT_GT(coupled.path_m, 15.0);
  // Measured over 20 s: 1.9 cm RMSE, 3.3 cm at the end; with the predicted twist: 10.8 cm, 15 cm
  // (session 20's second deskew after registration: 3.7 cm, 3.0 cm).
  EXPECT_LT(rmse(coupled), 0.04);
  EXPECT_LT(final_error(coupled), 0.06);
  EXPECT_GT(rmse(predicted), 3.0 * rmse(coupled));
}

TEST(LidarOdometry, UrbanVehicleOs1ThroughRainDriftsUnderHalfAPercent) {
  LidarOdometryConfig config;
  config.source_voxel_size = 1.0;
  // 70 s: 600 m of city streets, the rain episode (55-63 s: dropouts, phantom drops) included.
  const OdometryRun run = run_scenario("examples/scenarios/urban_vehicle.yaml", 70.0, config);
  ASSERT_GT(run.scans, 650U);
  EXPECT_GT(run.path_m, 400.0);
  auto kitti = eval::compute_kitti_odometry_error(run.truth, run.estimate);
  ASSERT_TRUE(kitti.ok()) << kitti.error().message;
  EXPECT_LT(kitti->translation_error_percent, 0.5);
  EXPECT_LT(kitti->rotation_error_deg_per_100m, 0.5);
  EXPECT_LT(final_error(run), 0.005 * run.path_m);
  // The rain (8 s = 80 sweeps) is flagged, clear weather is not.
  EXPECT_GT(run.weather_in_rain, 70U);
  EXPECT_LE(run.weather_outside, 3U);
  EXPECT_LT(run.phantoms_outside, 50U * run.scans);
}

TEST(LidarOdometry, UrbanVehicleHdl64KeepsTrackIntoTheFirstTurn) {
  // 130k points per sweep, -24..+2 deg: few high facade points. At the start of the first turn
  // (16 s) the constant-velocity prediction is 2-3 deg off in yaw; with a fixed 0.1 m kernel
  // this sensor lost track there (15 % drift), the coarse-to-fine kernel keeps it.
  LidarOdometryConfig config;
  const OdometryRun run = run_scenario("examples/scenarios/urban_vehicle.yaml", 22.0, config, sim::LidarModel::kVelodyneHdl64);
  ASSERT_GT(run.scans, 200U);
  EXPECT_GT(run.path_m, 140.0);
  EXPECT_LT(rmse(run), 0.1);
  EXPECT_LT(final_error(run), 0.005 * run.path_m);
}

cloud::PointCloud yard_scan(const SE3& T_world_sensor) {
  return testing_support::scan(testing_support::registration_world(), T_world_sensor, 0.01, 5);
}

// Points timed from -0.1 to 0 s (a sweep stamped at its end: its "middle" is the stamp) span
// twice the distance to the middle that the coupled deskew allows at 10 Hz: such sweeps keep the
// predicted twist instead of failing the registration.
TEST(LidarOdometry, SweepsTooLongForTheCoupledDeskewKeepThePredictedTwist) {
  const SE3 T_world_sensor = pose(0.3, -0.2, 1.8, 5);
  LidarOdometry odometry({}, T_world_sensor);
  for (int n = 0; n < 4; ++n) {
    cloud::PointCloud scan = yard_scan(T_world_sensor);
    scan.times.resize(scan.size());
    for (std::size_t i = 0; i < scan.size(); ++i) {
      scan.times[i] = -0.05F - 0.05F * std::atan2(scan.positions[i].y(), scan.positions[i].x()) / static_cast<float>(M_PI);
    }
    auto estimate = odometry.add_scan(Timestamp::from_seconds(100.0 + 0.1 * n), scan);
    ASSERT_TRUE(estimate.ok()) << "sweep " << n << ": " << estimate.error().message;
    EXPECT_LT((estimate->T_world_lidar.translation() - T_world_sensor.translation()).norm(), 0.01) << "sweep " << n;
  }
}

TEST(LidarOdometry, RefusesBadScansAndKeepsItsState) {
  LidarOdometry odometry({}, pose(0, 0, 1.8, 0));
  const Timestamp t0 = Timestamp::from_seconds(100.0);
  ASSERT_TRUE(odometry.add_scan(t0, yard_scan(pose(0, 0, 1.8, 0))).ok());
  auto second = odometry.add_scan(t0 + Duration::from_seconds(0.1), yard_scan(pose(0.2, 0, 1.8, 1)));
  ASSERT_TRUE(second.ok()) << second.error().message;
  EXPECT_LT((second->T_world_lidar.translation() - Eigen::Vector3d(0.2, 0, 1.8)).norm(), 0.02);
  const SE3 before = odometry.pose();
  const std::size_t map_points = odometry.local_map().point_count();

  auto repeated = odometry.add_scan(t0 + Duration::from_seconds(0.1), yard_scan(pose(0.2, 0, 1.8, 1)));
  ASSERT_FALSE(repeated.ok());
  EXPECT_NE(repeated.error().message.find("not after"), std::string::npos);
  cloud::PointCloud with_nan = yard_scan(pose(0.4, 0, 1.8, 2));
  with_nan.positions[3].x() = std::numeric_limits<float>::quiet_NaN();
  auto nan = odometry.add_scan(t0 + Duration::from_seconds(0.2), with_nan);
  ASSERT_FALSE(nan.ok());
  EXPECT_NE(nan.error().message.find("nan"), std::string::npos);
  cloud::PointCloud few;
  few.positions = {Eigen::Vector3f(3, 0, 0), Eigen::Vector3f(0, 3, 0)};
  auto too_few = odometry.add_scan(t0 + Duration::from_seconds(0.3), few);
  ASSERT_FALSE(too_few.ok());
  EXPECT_NE(too_few.error().message.find("points within"), std::string::npos);
  auto bad_prediction = odometry.add_scan(t0 + Duration::from_seconds(0.4), yard_scan(pose(0.4, 0, 1.8, 2)),
                                          SE3(SO3(), Eigen::Vector3d(std::numeric_limits<double>::infinity(), 0, 0)));
  EXPECT_NE(bad_prediction.error().message.find("motion"), std::string::npos);
  ASSERT_FALSE(bad_prediction.ok());
  EXPECT_EQ(odometry.scans(), 2U);
  EXPECT_EQ(odometry.local_map().point_count(), map_points);
  EXPECT_TRUE(odometry.pose().matrix().isApprox(before.matrix()));

  // And it goes on from where it was, here with a prediction (an IMU's in LiDAR-inertial mode).
  auto next = odometry.add_scan(t0 + Duration::from_seconds(0.5), yard_scan(pose(0.6, 0.1, 1.8, 3)),
                                before.inverse() * pose(0.5, 0.05, 1.8, 2));
  ASSERT_TRUE(next.ok()) << next.error().message;
  EXPECT_LT((next->T_world_lidar.translation() - Eigen::Vector3d(0.6, 0.1, 1.8)).norm(), 0.02);
  EXPECT_LT(rotation_error_deg(next->T_world_lidar, pose(0.6, 0.1, 1.8, 3)), 0.1);
}

}  // namespace
}  // namespace hanzo::fusion::lidar
