// hanzo-fusion slam2d LOG [--scale-error F] [--heading-drift DEG_PER_M] [--no-loop-closure]
//   [--trajectory OUT.tum] [--map OUT.yaml] [--plot DIR]:
// 2D laser SLAM (pipeline/planar_laser_slam.hpp) over a CARMEN log. The odometry is the scans'
// logged poses, optionally corrupted (the "corrected" Radish logs carry SLAM-corrected poses:
// corrupt them to test scan matching and loop closure against them). Reports the APE of the
// odometry and of the SLAM trajectory against the logged poses, per-scan latency and the
// time spent in each stage; writes the trajectory (TUM), an occupancy map (ROS map_server YAML
// + PGM) and an SVG of the trajectory. The outputs are written whether or not the evaluation
// can be computed (an undefined one says why).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/eval/plots.hpp"
#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/io/carmen_import.hpp"
#include "hanzo/fusion/maps/map_export.hpp"
#include "hanzo/fusion/maps/occupancy_grid.hpp"
#include "hanzo/fusion/pipeline/planar_laser_slam.hpp"
#include "hanzo/fusion/sim/planar_odometry_error.hpp"

namespace hanzo::fusion::app {
namespace {

struct Slam2dOptions {
  std::string log;
  double scale_error = 0.0;
  double heading_drift_deg_per_m = 0.0;
  bool no_loop_closure = false;
  std::string trajectory_out;
  std::string map_out;
  double map_resolution = 0.05;
  std::string plot_dir;
};


// Ray-casts every keyframe scan from its optimized pose.
Result<msgs::OccupancyGridLayer> occupancy_map(const pipeline::PlanarLaserSlam& slam, double resolution) {
  maps::OccupancyConfig config;
  config.resolution = resolution;
  auto grid = maps::OccupancyGrid<2>::create(config);
  if (!grid) return grid.error();
  for (size_t k = 0; k < slam.keyframe_count(); ++k) {
    const SE2 pose = slam.keyframe_pose(k);
    std::vector<Eigen::Vector2d> end_points;
    for (const Eigen::Vector2d& p : slam.keyframe_points(k)) end_points.push_back(pose * p);
    HANZO_RETURN_IF_ERROR(grid->insert_scan(pose.translation(), end_points));
  }
  return grid->to_layer();
}

int run_slam2d(const Output& output, const Slam2dOptions& options) {
  nlohmann::json result = {{"log", options.log}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  if (!std::isfinite(options.scale_error) || options.scale_error <= -1.0) return fail("--scale-error: must be a number > -1");
  if (!std::isfinite(options.heading_drift_deg_per_m)) return fail("--heading-drift: must be a number");
  auto log = io::read_carmen(options.log, {});
  if (!log) return fail(log.error().message);
  if (log->scans.empty()) return fail(fmt::format("{}: no FLASER scans", options.log));
  const io::Trajectory& logged = log->report.scan_poses;
  std::vector<SE2> logged_poses;
  for (const io::PoseMatrix& pose : logged.poses) logged_poses.push_back(io::planar_pose(pose));
  const std::vector<SE2> odometry =
      sim::corrupt_planar_odometry(logged_poses, {.scale_error = options.scale_error, .heading_drift_per_meter = options.heading_drift_deg_per_m * M_PI / 180.0});

  pipeline::PlanarLaserSlamConfig config;
  config.loop_closure = !options.no_loop_closure;
  pipeline::PlanarLaserSlam slam(config);
  std::vector<double> milliseconds;
  size_t refused = 0;
  std::string first_refusal;
  const auto start = std::chrono::steady_clock::now();
  for (size_t i = 0; i < log->scans.size(); ++i) {
    const auto scan_start = std::chrono::steady_clock::now();
    if (auto added = slam.add_scan(log->scans[i], odometry[i]); !added) {
      if (refused++ == 0) first_refusal = fmt::format("scan {}: {}", i, added.error().message);
      continue;
    }
    milliseconds.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - scan_start).count());
  }
  if (Status finished = slam.finish(); !finished) return fail(finished.error().message);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();

  const io::Trajectory estimate = slam.trajectory();
  // Compare on the scans the SLAM kept (refused ones have no pose).
  io::Trajectory reference, odometry_trajectory;
  for (size_t i = 0, e = 0; i < logged.size() && e < estimate.size(); ++i) {
    if (logged.timestamps[i] != estimate.timestamps[e]) continue;
    reference.timestamps.push_back(logged.timestamps[i]);
    reference.poses.push_back(logged.poses[i]);
    odometry_trajectory.timestamps.push_back(logged.timestamps[i]);
    odometry_trajectory.poses.push_back(io::pose_matrix(odometry[i]));
    ++e;
  }
  // The outputs first: an evaluation that cannot be computed (a degenerate alignment) is
  // reported as undefined, never a reason to throw the results away.
  std::string written;
  if (!options.trajectory_out.empty()) {
    if (Status status = io::write_trajectory(options.trajectory_out, estimate, io::TrajectoryFormat::kTum); !status) return fail(status.error().message);
    result["trajectory"] = options.trajectory_out;
    written += fmt::format("wrote {}\n", options.trajectory_out);
  }
  if (!options.map_out.empty()) {
    auto layer = occupancy_map(slam, options.map_resolution);
    if (!layer) return fail(layer.error().message);
    if (Status status = maps::write_ros_map(options.map_out, *layer); !status) return fail(status.error().message);
    result["map"] = options.map_out;
    written += fmt::format("wrote {} (+ .pgm)\n", options.map_out);
  }
  const eval::ApeConfig ape_config{.relation = eval::PoseRelation::kTranslation, .alignment = eval::Alignment::kSE3};
  auto odometry_ape = eval::compute_ape(reference, odometry_trajectory, ape_config);
  auto slam_ape = eval::compute_ape(reference, estimate, ape_config);

  std::sort(milliseconds.begin(), milliseconds.end());
  const auto percentile = [&](double p) { return milliseconds.empty() ? 0.0 : milliseconds[static_cast<size_t>(p * static_cast<double>(milliseconds.size() - 1))]; };
  const pipeline::PlanarLaserSlamSummary& summary = slam.summary();
  result["ok"] = true;
  result["scans"] = summary.scans;
  result["refused_scans"] = refused;
  if (refused > 0) result["first_refusal"] = first_refusal;
  result["keyframes"] = summary.keyframes;
  result["unmatched_scans"] = summary.unmatched_scans;
  result["degenerate_scans"] = summary.degenerate_scans;
  result["recovered_matches"] = summary.recovered_matches;
  result["loop_candidates"] = summary.loop_candidates;
  result["loop_closures"] = summary.loop_closures;
  result["optimizations"] = summary.optimizations;
  result["odometry_error"] = {{"scale_error", options.scale_error}, {"heading_drift_deg_per_m", options.heading_drift_deg_per_m}};
  if (!log->report.timestamp_warning.empty()) result["warnings"] = {log->report.timestamp_warning};
  std::string evaluation_text;
  if (odometry_ape && slam_ape) {
    result["ape_rmse_m"] = {{"odometry", odometry_ape->statistics.rmse}, {"slam", slam_ape->statistics.rmse}};
    result["ape_max_m"] = {{"odometry", odometry_ape->statistics.max}, {"slam", slam_ape->statistics.max}};
    evaluation_text = fmt::format("  APE RMSE against the logged poses: odometry {:.3f} m -> SLAM {:.3f} m (max {:.3f} m)\n",
                                  odometry_ape->statistics.rmse, slam_ape->statistics.rmse, slam_ape->statistics.max);
  } else {
    const std::string reason = !slam_ape ? slam_ape.error().message : odometry_ape.error().message;
    result["ape_rmse_m"] = {{"undefined", reason}};
    evaluation_text = fmt::format("  APE against the logged poses undefined: {}\n", reason);
  }
  result["seconds"] = {{"total", seconds},
                       {"scan_matching", summary.scan_matching_seconds},
                       {"loop_closure", summary.loop_closure_seconds},
                       {"optimization", summary.optimization_seconds}};
  result["scan_ms"] = {{"p50", percentile(0.5)}, {"p99", percentile(0.99)}, {"max", percentile(1.0)}};
  std::string text = fmt::format(
      "{}: {} scans ({} refused), {} keyframes, {} loop closures of {} candidates, {} scans unmatched, {} degenerate\n{}"
      "  {:.2f} s: scan matching {:.2f} s, loop closure {:.2f} s, optimization {:.2f} s ({} runs); per scan p50 {:.2f} ms, p99 {:.2f} ms, max {:.2f} ms\n{}",
      options.log, summary.scans, refused, summary.keyframes, summary.loop_closures, summary.loop_candidates, summary.unmatched_scans,
      summary.degenerate_scans, evaluation_text, seconds, summary.scan_matching_seconds, summary.loop_closure_seconds,
      summary.optimization_seconds, summary.optimizations, percentile(0.5), percentile(0.99), percentile(1.0), written);
  if (!options.plot_dir.empty() && slam_ape) {
    std::error_code ec;
    std::filesystem::create_directories(options.plot_dir, ec);
    if (ec) return fail(fmt::format("{}: cannot create plot folder ({})", options.plot_dir, ec.message()));
    const std::string path = (std::filesystem::path(options.plot_dir) / "slam2d_trajectory.svg").string();
    const std::string svg = eval::trajectory_top_view_svg(reference, slam_ape->estimate_aligned, slam_ape->errors,
                                                          {"2D laser SLAM (coloured by APE) over the logged poses (grey)", "APE (m)"});
    if (Status status = eval::write_svg(path, svg); !status) return fail(status.error().message);
    result["plots"] = {path};
    text += fmt::format("plot: {}\n", path);
  }
  return report_success(output, result, text);
}

}  // namespace

void add_slam2d_command(CLI::App& app, const Output& output, Command& run) {
  auto options = std::make_shared<Slam2dOptions>();
  CLI::App* command = app.add_subcommand("slam2d", "2D laser SLAM over a CARMEN log: scan matching, loop closure, pose graph");
  command->add_option("LOG", options->log, "CARMEN log (FLASER lines; plain or .gz)")->required();
  command->add_option("--scale-error", options->scale_error, "Odometry made this much too long (0.05: 5 %)")->capture_default_str();
  command->add_option("--heading-drift", options->heading_drift_deg_per_m, "Odometry heading drift, degrees per metre driven")->capture_default_str();
  command->add_flag("--no-loop-closure", options->no_loop_closure, "Scan-to-map odometry only");
  command->add_option("--trajectory", options->trajectory_out, "Write the SLAM trajectory (TUM)");
  command->add_option("--map", options->map_out, "Write an occupancy map (ROS map_server YAML + PGM)");
  command->add_option("--map-resolution", options->map_resolution, "Cell size of --map (m)")->capture_default_str();
  command->add_option("--plot", options->plot_dir, "Write an SVG of the trajectory coloured by error into this folder");
  command->callback([&output, &run, options] { run = [&output, options] { return run_slam2d(output, *options); }; });
}

}  // namespace hanzo::fusion::app
