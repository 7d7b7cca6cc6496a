// hanzo-fusion map localize MAP SCAN: where a LiDAR scan was taken in a FusionMap's point layer
// (lidar::MapLocalizer; docs/lidar-odometry.md): a global search without --guess, a window
// around it with. Prints the pose and the checks' numbers (--json: one object); exits 1 with the
// reason when no pose verifies or the scan fits several places alike.

#include <cmath>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/cloud/cloud_io.hpp"
#include "hanzo/fusion/lidar/map_localization.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"

namespace hanzo::fusion::app {
namespace {

struct LocalizeOptions {
  std::string map;
  std::string scan;
  std::vector<double> guess;          // x, y, z (m), yaw (deg)
  double window = 5.0;                // m
  double angular_window_deg = 30.0;
  std::vector<double> roll_pitch_deg{0.0, 0.0};
  bool indoor = false;
};

SO3 rotation_from(double roll, double pitch, double yaw) {
  return SO3::from_axis_angle(Eigen::Vector3d::UnitZ(), yaw) * SO3::from_axis_angle(Eigen::Vector3d::UnitY(), pitch) *
         SO3::from_axis_angle(Eigen::Vector3d::UnitX(), roll);
}

int run_localize(const Output& output, const LocalizeOptions& options) {
  nlohmann::json result = {{"map", options.map}, {"scan", options.scan}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  auto map = maps::read_fusion_map(options.map);
  if (!map) return fail(map.error().message);
  if (!map->points || map->points->points.empty()) return fail(fmt::format("{}: the map has no point layer to localize in", options.map));
  auto scan = cloud::read_cloud(options.scan);
  if (!scan) return fail(scan.error().message);
  constexpr double kDegree = std::numbers::pi / 180.0;
  lidar::LidarOdometryConfig odometry;
  if (options.indoor) {
    odometry.map.voxel_size = 0.5;
    odometry.source_voxel_size = 0.25;
  }
  auto localizer = lidar::MapLocalizer::create(map->points->points, {}, odometry);
  if (!localizer) return fail(localizer.error().message);
  const SO3 R_up_sensor = rotation_from(options.roll_pitch_deg[0] * kDegree, options.roll_pitch_deg[1] * kDegree, 0.0);
  lidar::MapLocalizationQuery query;
  if (!options.guess.empty()) {
    query.T_map_sensor_guess = SE3(rotation_from(options.roll_pitch_deg[0] * kDegree, options.roll_pitch_deg[1] * kDegree, options.guess[3] * kDegree),
                                   Eigen::Vector3d(options.guess[0], options.guess[1], options.guess[2]));
    query.linear_window = options.window;
    query.angular_window = options.angular_window_deg * kDegree;
  }
  auto found = localizer->localize(scan->positions, R_up_sensor, query);
  if (!found) return fail(found.error().message);
  const SE3& pose = found->T_map_sensor;
  const Eigen::Quaterniond q = pose.rotation().quaternion();
  const Eigen::Matrix3d R = pose.rotation().matrix();
  const double yaw_deg = std::atan2(R(1, 0), R(0, 0)) / kDegree;
  result["position"] = {pose.translation().x(), pose.translation().y(), pose.translation().z()};
  result["orientation_wxyz"] = {q.w(), q.x(), q.y(), q.z()};
  result["yaw_deg"] = yaw_deg;
  result["global_search"] = found->global;
  result["score"] = found->score;
  result["inlier_rmse_m"] = found->inlier_rmse;
  result["inlier_fraction"] = found->inlier_fraction;
  result["seen_through_fraction"] = found->seen_through_fraction;
  result["headings"] = found->headings;
  result["nodes_evaluated"] = found->nodes_evaluated;
  result["seconds"] = found->seconds;
  return report_success(output, result,
                        fmt::format("{} in {}: position {:.3f} {:.3f} {:.3f} m, yaw {:.2f} deg ({} search, score {:.2f}, RMSE {:.3f} m, "
                                    "{:.0f} % matched, {:.0f} % seen through, {:.2f} s)\n",
                                    options.scan, options.map, pose.translation().x(), pose.translation().y(), pose.translation().z(), yaw_deg,
                                    found->global ? "global" : "windowed", found->score, found->inlier_rmse, 100.0 * found->inlier_fraction,
                                    100.0 * found->seen_through_fraction, found->seconds));
}

}  // namespace

void add_map_localize_command(CLI::App& map_app, const Output& output, Command& run) {
  auto options = std::make_shared<LocalizeOptions>();
  CLI::App* command = map_app.add_subcommand("localize", "Where a LiDAR scan was taken in a map (global search, or around --guess)");
  command->add_option("MAP", options->map, "FusionMap file with a point layer (z up)")->required()->check(CLI::ExistingFile);
  command->add_option("SCAN", options->scan, "The scan in its sensor frame: PCD, PLY or KITTI .bin")->required()->check(CLI::ExistingFile);
  command->add_option("--guess", options->guess, "x y z (m) yaw (deg) of the sensor in the map: search only around it")->expected(4);
  command->add_option("--window", options->window, "m searched around --guess")->capture_default_str()->check(CLI::Range(0.0, 1e4));
  command->add_option("--angular-window", options->angular_window_deg, "deg searched around --guess's yaw")
      ->capture_default_str()->check(CLI::Range(0.0, 180.0));
  command->add_option("--roll-pitch", options->roll_pitch_deg, "The sensor's roll and pitch (deg) against gravity (an IMU gives them)")
      ->expected(2)->capture_default_str();
  command->add_flag("--indoor", options->indoor, "Indoor registration settings (0.25 m points, 0.5 m map voxels)");
  command->callback([&output, &run, options] { run = [&output, options] { return run_localize(output, *options); }; });
}

}  // namespace hanzo::fusion::app
