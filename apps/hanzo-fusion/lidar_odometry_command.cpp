// hanzo-fusion lidar-odometry LOG [--topic T] [--ground-truth GT.tum] [--calibration CALIB.yaml]
//   [--fusion-config FUSION.yaml] [--voxel M] [--source-voxel M] [--threads N] [--max-range M]
//   [--no-deskew] [--deskew-coupling T,R] [--max-scans N] [--trajectory OUT.tum] [--plot DIR]:
// LiDAR odometry (lidar/lidar_odometry.hpp) over the point clouds of a sensor log; with
// --fusion-config, LiDAR-inertial: the log's IMU and this LiDAR through a pipeline::Session in
// replay mode, as `hanzo-fusion run --sensors IMU,LIDAR` runs them (the reported trajectory is
// the filter's pose at each sweep's middle; --loop-closure closes loops in it). With a ground
// truth (T_world_body, TUM) the body trajectory is scored: KITTI drift (% and deg/100 m, when
// the path is longer than 100 m), APE RMSE and final position error (LiDAR only: from the true
// first pose, no alignment; LiDAR-inertial: after a rigid alignment, the Session's frame being
// its own); a score that cannot be computed is reported as undefined, the trajectory is written
// first. Reports per-scan latency by stage, degenerate scans and the local map's size.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/calib/calibration.hpp"
#include "hanzo/fusion/cloud/point_cloud.hpp"
#include "hanzo/fusion/eval/association.hpp"
#include "hanzo/fusion/eval/kitti_odometry.hpp"
#include "hanzo/fusion/eval/plots.hpp"
#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/lidar/lidar_odometry.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/pipeline/lidar_slam.hpp"
#include "hanzo/fusion/config/fusion_config.hpp"

namespace hanzo::fusion::app {
namespace {

struct LidarOdometryOptions {
  std::string log;
  std::string topic;
  std::string ground_truth;
  std::string calibration;
  std::string fusion_config;
  double voxel = 1.0;
  double source_voxel = 1.0;
  int threads = 1;
  double max_range = 100.0;
  bool no_deskew = false;
  std::vector<double> deskew_coupling{lidar::LidarOdometryConfig{}.deskew_translation_coupling, lidar::LidarOdometryConfig{}.deskew_rotation_coupling};
  bool loop_closure = false;
  std::size_t max_scans = 0;
  std::string trajectory_out;
  std::string plot_dir;
};

// The scored part of the report (ground truth given).
// `aligned`: the estimate's world frame is its own (LiDAR-inertial: the Frontend's), so APE and
// the final error are taken after a rigid alignment; the KITTI drift needs none.
Status score(const io::Trajectory& estimate, const io::Trajectory& ground_truth, const LidarOdometryOptions& options,
             bool aligned, nlohmann::json& result, std::string& text) {
  eval::AssociatedTrajectories pairs;
  HANZO_ASSIGN_OR_RETURN(pairs, eval::associate(ground_truth, estimate));
  eval::ApeResult ape;
  HANZO_ASSIGN_OR_RETURN(ape, eval::compute_ape(pairs.reference, pairs.estimate,
                                                {.alignment = aligned ? eval::Alignment::kSE3 : eval::Alignment::kNone}));
  const double path = pairs.reference.path_length();
  const double final_error = (ape.reference.position(ape.reference.size() - 1) -
                              ape.estimate_aligned.position(ape.estimate_aligned.size() - 1)).norm();
  result["path_m"] = path;
  result["ape_rmse_m"] = ape.statistics.rmse;
  result["ape_max_m"] = ape.statistics.max;
  result["final_position_error_m"] = final_error;
  text += fmt::format("  against the ground truth over {:.1f} m: APE RMSE {:.3f} m (max {:.3f} m), final position error {:.3f} m ({:.2f} % of the path)\n",
                      path, ape.statistics.rmse, ape.statistics.max, final_error, 100.0 * final_error / std::max(path, 1e-9));
  if (auto kitti = eval::compute_kitti_odometry_error(pairs.reference, pairs.estimate); kitti) {
    result["kitti"] = {{"translation_percent", kitti->translation_error_percent},
                       {"rotation_deg_per_100m", kitti->rotation_error_deg_per_100m},
                       {"segments", static_cast<std::size_t>(kitti->segments)}};
    text += fmt::format("  KITTI drift: {:.2f} %, {:.3f} deg/100 m ({} segments)\n", kitti->translation_error_percent,
                        kitti->rotation_error_deg_per_100m, kitti->segments);
  }
  if (!options.plot_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(options.plot_dir, ec);
    if (ec) return Error(fmt::format("{}: cannot create plot folder ({})", options.plot_dir, ec.message()));
    const std::string path_svg = (std::filesystem::path(options.plot_dir) / "lidar_odometry_trajectory.svg").string();
    HANZO_RETURN_IF_ERROR(eval::write_svg(path_svg, eval::trajectory_top_view_svg(pairs.reference, ape.estimate_aligned, ape.errors,
                                                                                  {"LiDAR odometry (coloured by error) over the ground truth (grey)", "error (m)"})));
    result["plots"] = {path_svg};
    text += fmt::format("plot: {}\n", path_svg);
  }
  return ok_status();
}

int run_lidar_odometry(const Output& output, const LidarOdometryOptions& options) {
  nlohmann::json result = {{"log", options.log}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  lidar::LidarOdometryConfig config;
  config.map.voxel_size = options.voxel;
  config.source_voxel_size = options.source_voxel;
  config.num_threads = options.threads;
  config.registration.max_neighbour_distance = options.voxel;
  config.max_range = options.max_range;
  config.deskew = !options.no_deskew;
  config.deskew_translation_coupling = options.deskew_coupling[0];
  config.deskew_rotation_coupling = options.deskew_coupling[1];
  if (Status valid = config.validate(); !valid) return fail(valid.error().message);

  SE3 T_body_lidar;
  std::optional<io::Trajectory> ground_truth;
  if (!options.ground_truth.empty()) {
    auto read = io::read_trajectory(options.ground_truth, io::TrajectoryFormat::kTum);
    if (!read) return fail(read.error().message);
    ground_truth = std::move(*read);
  }
  auto reader = io::SensorLogReader::open(options.log);
  if (!reader) return fail(reader.error().message);

  std::string topic = options.topic;
  std::unique_ptr<lidar::LidarOdometry> odometry;              // LiDAR only
  std::unique_ptr<pipeline::LidarSlam> slam;                   // LiDAR only, --loop-closure
  std::unique_ptr<pipeline::Session> session;  // LiDAR-inertial
  std::string lidar_sensor;
  io::Trajectory estimate;
  std::vector<double> milliseconds;
  std::size_t weather = 0, phantoms = 0;
  std::size_t refused = 0, degenerate = 0, max_map_points = 0, max_map_bytes = 0, iterations = 0, associations = 0;
  double stage_seconds[3] = {0.0, 0.0, 0.0};
  std::string first_refusal;

  // One registered sweep: its statistics and the body pose (T_world_body at the sweep's middle).
  const auto record_estimate = [&](const lidar::LidarOdometryEstimate& added, double scan_ms, std::size_t local_map_bytes,
                                   const SE3& T_world_body) {
    milliseconds.push_back(scan_ms);
    degenerate += added.degenerate ? 1 : 0;
    weather += added.weather_degraded ? 1 : 0;
    phantoms += added.phantom_points;
    iterations += static_cast<std::size_t>(added.iterations);
    associations += static_cast<std::size_t>(added.associations);
    stage_seconds[0] += added.preprocess_seconds;
    stage_seconds[1] += added.registration_seconds;
    stage_seconds[2] += added.map_update_seconds;
    max_map_points = std::max(max_map_points, added.map_points);
    max_map_bytes = std::max(max_map_bytes, local_map_bytes);
    estimate.timestamps.push_back(added.time);
    estimate.poses.push_back(T_world_body.matrix());
  };
  // A sweep the Session registered: the fused estimate is the filter's pose at the sweep's middle.
  const auto record = [&](const pipeline::LidarInertialOdometry::RegisteredScan& registered) {
    const lidar::LidarOdometryEstimate& added = registered.estimate;
    const SE3 fused = session->frontend().pose_at(added.time).value_or(registered.T_world_lidar * T_body_lidar.inverse());
    record_estimate(added, 1e3 * registered.seconds, 0, fused);
  };

  // The first sweep fixes the topic, the LiDAR's calibration and the starting pose.
  const auto start_with = [&](const msgs::PointCloudMessage& scan, const std::string& scan_topic) -> Status {
    topic = scan_topic;
    std::optional<calib::Calibration> calibration;
    if (!options.calibration.empty()) {
      auto loaded = calib::load_calibration(options.calibration);
      if (!loaded) return loaded.error();
      calibration = std::move(*loaded);
    }
    if (!options.fusion_config.empty()) {
      if (!calibration) return Error("--fusion-config needs --calibration");
      auto fusion = config::load_fusion_config(options.fusion_config);
      if (!fusion) return fusion.error();
      const config::SensorConfig* sensor = nullptr;
      for (const config::SensorConfig& candidate : fusion->sensors) {
        if (candidate.topic == topic) sensor = &candidate;
      }
      if (sensor == nullptr) return Error(fmt::format("{}: no sensor reads {}", options.fusion_config, topic));
      lidar_sensor = sensor->name;
      // Only what this command feeds: the IMU and this LiDAR (no timeouts of other sensors).
      std::erase_if(fusion->sensors, [&](const config::SensorConfig& s) { return s.name != lidar_sensor && s.modality != config::SensorModality::kImu; });
      pipeline::SessionConfig session_config = pipeline::SessionConfig::from(*fusion);
      session_config.lidar_odometry.odometry = config;
      session_config.loop_closure = options.loop_closure;
      session_config.num_threads = options.threads;
      auto created = pipeline::Session::create(*fusion, *calibration, session_config);
      if (!created) return created.error();
      session = std::move(*created);
      if (const calib::SensorCalibration* entry = calibration->find(lidar_sensor)) T_body_lidar = entry->T_body_sensor();
      session->set_scan_callback([&](const pipeline::LidarInertialOdometry::RegisteredScan& registered) { record(registered); });
      return ok_status();
    }
    if (calibration) {
      const calib::SensorCalibration* sensor = calibration->find(scan.frame_id);
      if (sensor == nullptr) return Error(fmt::format("{}: no calibration for frame '{}'", options.calibration, scan.frame_id));
      T_body_lidar = sensor->T_body_sensor();
    }
    SE3 initial_pose;
    if (ground_truth) {
      // Estimates refer to the middle of each sweep.
      Timestamp middle = scan.timestamp;
      if (!scan.point_timestamps.empty()) {
        middle = scan.timestamp + Duration::from_nanoseconds((scan.point_timestamps.back() - scan.timestamp).nanoseconds() / 2);
      }
      io::Trajectory first;
      first.timestamps.push_back(middle);
      first.poses.push_back(Eigen::Matrix4d::Identity());
      auto pair = eval::associate(*ground_truth, first);
      if (!pair) return Error(fmt::format("ground truth at the first scan: {}", pair.error().message));
      initial_pose = pair->reference.pose_se3(0) * T_body_lidar;
    }
    if (options.loop_closure) {
      pipeline::LidarSlamConfig slam_config;
      slam_config.odometry = config;
      slam = std::make_unique<pipeline::LidarSlam>(slam_config, initial_pose);
    } else {
      odometry = std::make_unique<lidar::LidarOdometry>(config, initial_pose);
    }
    return ok_status();
  };

  // LiDAR only.
  const auto register_scan = [&](const msgs::PointCloudMessage& scan) {
    const auto start = std::chrono::steady_clock::now();
    Result<lidar::LidarOdometryEstimate> added = Error("");
    if (auto cloud = cloud::from_message(scan); cloud) {
      added = slam ? slam->add_scan(scan.timestamp, *cloud) : odometry->add_scan(scan.timestamp, *cloud);
    } else {
      added = cloud.error();
    }
    if (!added) {
      if (refused++ == 0) first_refusal = fmt::format("scan at {:.3f} s: {}", scan.timestamp.seconds(), added.error().message);
      return;
    }
    const lidar::LidarOdometry& used = slam ? slam->odometry() : *odometry;
    record_estimate(*added, std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count(),
                    used.local_map().memory_bytes(), added->T_world_lidar * T_body_lidar.inverse());
  };

  io::LogEntry entry;
  while (options.max_scans == 0 || milliseconds.size() + refused < options.max_scans) {
    auto more = (*reader)->next(entry);
    if (!more) return fail(more.error().message);
    if (!*more) break;
    const auto* message = std::get_if<msgs::SensorMessage>(&entry.message);
    if (message == nullptr) continue;
    const auto* scan = std::get_if<msgs::PointCloudMessage>(message);
    if (scan != nullptr && topic.empty()) topic = entry.topic;  // the first point-cloud topic
    if (scan != nullptr && entry.topic == topic && !odometry && !session && !slam) {
      if (Status started = start_with(*scan, entry.topic); !started) return fail(started.error().message);
    }
    if (session) {
      // The IMU and this LiDAR; rejections and sweeps that do not register are counted by the session.
      if (const config::SensorConfig* sensor = session->frontend().sensor_for_topic(entry.topic)) (void)session->push(sensor->name, *message);
      continue;
    }
    if (scan != nullptr && entry.topic == topic && (odometry || slam)) register_scan(*scan);
  }
  const bool read_to_the_end = options.max_scans == 0 || milliseconds.size() + refused < options.max_scans;
  if (Status whole = (*reader)->complete(); read_to_the_end && !whole) return fail(whole.error().message);
  if (session) {
    session->flush();
    refused = session->mapping_summary().scans_refused;
    if (refused > 0) first_refusal = "see the session's LiDAR counters (aligning, not_registered)";
  }
  if (!odometry && !session && !slam) return fail(fmt::format("{}: no point clouds{}", options.log, topic.empty() ? "" : " on " + topic));
  if (milliseconds.empty()) return fail(fmt::format("every scan was refused; first: {}", first_refusal));

  std::vector<double> sorted = milliseconds;
  std::sort(sorted.begin(), sorted.end());
  const auto percentile = [&](double p) { return sorted[static_cast<std::size_t>(p * static_cast<double>(sorted.size() - 1))]; };
  double total_ms = 0.0;
  for (double ms : milliseconds) total_ms += ms;
  result["ok"] = true;
  result["topic"] = topic;
  result["mode"] = session ? "lidar-inertial" : "lidar";
  result["scans"] = milliseconds.size();
  result["refused_scans"] = refused;
  if (refused > 0) result["first_refusal"] = first_refusal;
  result["degenerate_scans"] = degenerate;
  result["weather_degraded_scans"] = weather;
  result["phantom_points"] = phantoms;
  const double scans = static_cast<double>(milliseconds.size());
  result["mean_iterations"] = static_cast<double>(iterations) / scans;
  result["mean_associations"] = static_cast<double>(associations) / scans;
  result["scan_ms"] = {{"mean", total_ms / static_cast<double>(milliseconds.size())}, {"p50", percentile(0.5)}, {"p99", percentile(0.99)}, {"max", percentile(1.0)}};
  result["stage_ms"] = {{"preprocess", 1e3 * stage_seconds[0] / scans},
                        {"registration", 1e3 * stage_seconds[1] / scans},
                        {"map_update", 1e3 * stage_seconds[2] / scans}};
  result["local_map"] = {{"max_points", max_map_points}, {"max_bytes", max_map_bytes}};
  std::string text = fmt::format(
      "{} ({}): {} scans ({} refused), {} degenerate, {} weather-degraded ({} phantom returns dropped), {:.1f} iterations and {:.1f} surface fits per scan; per scan mean "
      "{:.1f} ms (preprocess {:.1f}, registration {:.1f}, map update {:.1f}), p50 {:.1f}, p99 {:.1f}, max {:.1f} ms; "
      "local map up to {} points, {:.1f} MB\n",
      options.log, topic, milliseconds.size(), refused, degenerate, weather, phantoms, static_cast<double>(iterations) / scans,
      static_cast<double>(associations) / scans, total_ms / scans, 1e3 * stage_seconds[0] / scans,
      1e3 * stage_seconds[1] / scans, 1e3 * stage_seconds[2] / scans,
      percentile(0.5), percentile(0.99), percentile(1.0), max_map_points, static_cast<double>(max_map_bytes) / 1e6);
  if (slam) {
    const pipeline::LidarSlamSummary& summary = slam->summary();
    result["loop_closure"] = {{"keyframes", summary.keyframes}, {"candidates", summary.loop_candidates},
                              {"closures", summary.loop_closures}, {"optimizations", summary.optimizations},
                              {"loop_closure_seconds", summary.loop_closure_seconds},
                              {"optimization_seconds", summary.optimization_seconds}};
    text += fmt::format("  loop closure: {} keyframes, {} of {} candidates verified, {} optimizations ({:.2f} s verifying, {:.2f} s optimizing)\n",
                        summary.keyframes, summary.loop_closures, summary.loop_candidates, summary.optimizations,
                        summary.loop_closure_seconds, summary.optimization_seconds);
  }
  if (session) {
    const pipeline::MappingSummary mapping = session->mapping_summary();
    result["loop_closure"] = {{"enabled", options.loop_closure}, {"map_keyframes", mapping.map_keyframes},
                              {"candidates", mapping.loop_candidates}, {"closures", mapping.loop_closures}};
    if (options.loop_closure) {
      text += fmt::format("  loop closure: {} map keyframes, {} of {} candidates verified\n", mapping.map_keyframes, mapping.loop_closures,
                          mapping.loop_candidates);
    }
  }
  // Every sweep through the optimized keyframe graph (LiDAR SLAM).
  std::optional<io::Trajectory> corrected;
  if (slam) {
    corrected = slam->trajectory();
    for (Eigen::Matrix4d& pose : corrected->poses) pose = pose * T_body_lidar.inverse().matrix();
  }
  // Outputs first: a score that cannot be computed does not lose them.
  if (!options.trajectory_out.empty()) {
    if (Status written = io::write_trajectory(options.trajectory_out, corrected ? *corrected : estimate, io::TrajectoryFormat::kTum); !written) {
      return fail(written.error().message);
    }
    result["trajectory"] = options.trajectory_out;
  }
  if (ground_truth) {
    const auto scored = [&](const io::Trajectory& trajectory, bool aligned, const std::string& heading) {
      nlohmann::json scores;
      std::string scored_text = heading;
      if (Status status = score(trajectory, *ground_truth, options, aligned, scores, scored_text); !status) {
        scores = {{"undefined", status.error().message}};
        scored_text = heading + fmt::format("  score undefined: {}\n", status.error().message);
      }
      text += scored_text;
      return scores;
    };
    nlohmann::json odometry_result = scored(estimate, session != nullptr, slam ? "  odometry (before loop closure):\n" : "");
    if (corrected) {
      result["odometry"] = odometry_result;
      result["slam"] = scored(*corrected, false, "  after loop closure:\n");
    } else {
      result.update(odometry_result);
    }
  }
  if (!options.trajectory_out.empty()) text += fmt::format("wrote {}\n", options.trajectory_out);
  return report_success(output, result, text);
}

}  // namespace

void add_lidar_odometry_command(CLI::App& app, const Output& output, Command& run) {
  auto options = std::make_shared<LidarOdometryOptions>();
  CLI::App* command = app.add_subcommand("lidar-odometry", "LiDAR odometry over a sensor log's point clouds (scan to local map)");
  command->add_option("LOG", options->log, "Sensor log (MCAP, e.g. from hanzo-fusion sim or import)")->required();
  command->add_option("--topic", options->topic, "Point-cloud topic (default: the first one)");
  command->add_option("--ground-truth,--gt", options->ground_truth, "Ground truth T_world_body (TUM): start there and score the result");
  command->add_option("--calibration,--calib", options->calibration, "Calibration YAML with <frame_id>_to_body of the LiDAR (default: identity)");
  command->add_option("--fusion-config", options->fusion_config,
                      "LiDAR-inertial: run a Session with this fusion configuration (needs --calibration) on the log's IMU and this LiDAR")
      ->check(CLI::ExistingFile);
  command->add_option("--voxel", options->voxel, "Local map voxel size and neighbour radius, m")->capture_default_str();
  command->add_option("--source-voxel", options->source_voxel, "Registration points downsampled to this, m (1.0 outdoor, 0.25 indoor)")->capture_default_str();
  command->add_option("--threads", options->threads, "Registration threads (0: all cores)")->capture_default_str();
  command->add_option("--max-range", options->max_range, "Ignore returns farther than this, m")->capture_default_str();
  command->add_flag("--no-deskew", options->no_deskew, "Use the points as measured (no motion compensation)");
  command->add_option("--deskew-coupling", options->deskew_coupling,
                      "LiDAR only: how the deskew twist's translation and rotation follow the registered pose (1.5: constant "
                      "acceleration, 1: the mean twist since the last sweep, 0: the predicted twist)")
      ->expected(2)
      ->delimiter(',')
      ->capture_default_str();
  command->add_flag("--loop-closure", options->loop_closure,
                    "Scan Context loop closure: LiDAR only, a keyframe pose graph (scores before and after); with --fusion-config, the Session's");
  command->add_option("--max-scans", options->max_scans, "Stop after this many scans (0: all)");
  command->add_option("--trajectory", options->trajectory_out, "Write the body trajectory (TUM)");
  command->add_option("--plot", options->plot_dir, "Write an SVG of the trajectory against the ground truth into this folder");
  command->callback([&output, &run, options] { run = [&output, options] { return run_lidar_odometry(output, *options); }; });
}

}  // namespace hanzo::fusion::app
