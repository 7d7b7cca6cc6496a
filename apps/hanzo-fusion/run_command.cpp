// hanzo-fusion run --config C.yaml --calib K.yaml --log L.mcap --out DIR [--gt GT.tum]: replays a
// sensor log through a pipeline::Frontend and writes what it estimated:
//   DIR/trajectory.tum    every PoseEstimate (IMU rate)
//   DIR/poses.csv         the same with velocity, status and the 6x6 pose covariance
//   DIR/innovations.csv   every measurement update: sensor, model, time, d^2, applied, innovation
//   DIR/keyframes.csv     keyframes for the backend: pose, relative motion and its covariance
//   DIR/summary.json      per-sensor counts, rates, rejections by reason, NIS, timing
//   DIR/*.svg             trajectory (coloured by position sigma), covariance over time, NIS per sensor
// With --gt it also computes APE without alignment (the world frames agree when the datum or
// start pose is shared) and SE3-aligned (they need not), and RPE over 1 m steps.

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>

#include <fmt/format.h>

#include "commands.hpp"
#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/eval/association.hpp"
#include "hanzo/fusion/eval/plots.hpp"
#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/eval/statistics.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/maps/map_export.hpp"
#include "hanzo/fusion/maps/provenance.hpp"
#include "hanzo/fusion/pipeline/log_replay.hpp"
#include "hanzo/fusion/pipeline/session.hpp"

namespace hanzo::fusion::app {
namespace {

struct RunOptions {
  std::string config_path;
  std::string calibration_path;
  std::string log_path;
  std::string out;
  std::string ground_truth;
  int threads = 1;
  std::vector<std::string> sensors;  // empty: every configured sensor
};

// A progress bar on stderr, only when stderr is a terminal.
class ProgressBar {
 public:
  explicit ProgressBar(Timestamp start, Timestamp end) : start_(start), end_(end), enabled_(isatty(STDERR_FILENO) != 0) {}
  void update(Timestamp now) {
    if (!enabled_ || end_ <= start_) return;
    const int percent = static_cast<int>(100.0 * (now - start_).seconds() / (end_ - start_).seconds());
    if (percent == last_percent_) return;
    last_percent_ = percent;
    const int filled = percent * 40 / 100;
    std::fprintf(stderr, "\r[%s%s] %3d%%", std::string(static_cast<size_t>(filled), '#').c_str(),
                 std::string(static_cast<size_t>(40 - filled), ' ').c_str(), percent);
  }
  void finish() {
    if (enabled_) std::fprintf(stderr, "\n");
  }

 private:
  Timestamp start_, end_;
  bool enabled_;
  int last_percent_ = -1;
};

io::Trajectory trajectory_of(const std::vector<msgs::PoseEstimate>& poses) {
  io::Trajectory trajectory;
  for (const msgs::PoseEstimate& pose : poses) {
    if (!trajectory.timestamps.empty() && pose.timestamp <= trajectory.timestamps.back()) continue;
    trajectory.timestamps.push_back(pose.timestamp);
    trajectory.poses.push_back(pose.T_world_body.to_se3().matrix());
  }
  return trajectory;
}

Status write_poses_csv(const std::string& path, const std::vector<msgs::PoseEstimate>& poses) {
  std::ofstream file(path);
  if (!file) return Error(fmt::format("{}: cannot write", path));
  file << "timestamp_ns,x,y,z,qw,qx,qy,qz,vx,vy,vz,state,active_modalities";
  for (int i = 0; i < 6; ++i) {
    for (int j = i; j < 6; ++j) file << ",cov_" << i << j;
  }
  file << "\n";
  for (const msgs::PoseEstimate& pose : poses) {
    const auto& p = pose.T_world_body.position;
    const auto& q = pose.T_world_body.orientation;
    file << fmt::format("{},{},{},{},{},{},{},{},{},{},{},{},{}", pose.timestamp.nanoseconds(), p.x(), p.y(), p.z(), q.w(), q.x(),
                        q.y(), q.z(), pose.velocity.x(), pose.velocity.y(), pose.velocity.z(), msgs::to_string(pose.status.state),
                        pose.status.active_modalities);
    const msgs::Matrix6d covariance = pose.pose_covariance.value_or(msgs::Matrix6d::Zero());
    for (int i = 0; i < 6; ++i) {
      for (int j = i; j < 6; ++j) file << "," << fmt::format("{}", covariance(i, j));
    }
    file << "\n";
  }
  return file ? ok_status() : Status(Error(fmt::format("{}: write failed", path)));
}

io::Trajectory trajectory_of(const std::vector<pipeline::StampedPose>& poses) {
  io::Trajectory trajectory;
  for (const pipeline::StampedPose& pose : poses) {
    trajectory.timestamps.push_back(pose.timestamp);
    trajectory.poses.push_back(pose.T_world_body.matrix());
  }
  return trajectory;
}

Status write_keyframes_csv(const std::string& path, const std::vector<msgs::Keyframe>& keyframes, const pipeline::Session& session) {
  std::ofstream file(path);
  if (!file) return Error(fmt::format("{}: cannot write", path));
  file << "keyframe_id,timestamp_ns,x,y,z,qw,qx,qy,qz,opt_x,opt_y,opt_z,opt_qw,opt_qx,opt_qy,opt_qz,"
          "previous_id,rel_x,rel_y,rel_z,rel_qw,rel_qx,rel_qy,rel_qz";
  for (int i = 0; i < 6; ++i) {
    for (int j = i; j < 6; ++j) file << ",rel_cov_" << i << j;
  }
  file << "\n";
  for (const msgs::Keyframe& k : keyframes) {
    const auto& p = k.T_world_body.position;
    const auto& q = k.T_world_body.orientation;
    file << fmt::format("{},{},{},{},{},{},{},{},{}", k.keyframe_id, k.timestamp.nanoseconds(), p.x(), p.y(), p.z(), q.w(), q.x(), q.y(), q.z());
    if (const std::optional<SE3> optimized = session.keyframe_pose(k.keyframe_id)) {
      const Eigen::Vector3d t = optimized->translation();
      const Eigen::Quaterniond r = optimized->rotation().quaternion();
      file << fmt::format(",{},{},{},{},{},{},{}", t.x(), t.y(), t.z(), r.w(), r.x(), r.y(), r.z());
    } else {
      file << std::string(7, ',');
    }
    if (k.T_previous_current && k.relative_covariance) {
      const auto& rp = k.T_previous_current->position;
      const auto& rq = k.T_previous_current->orientation;
      file << fmt::format(",{},{},{},{},{},{},{},{}", k.previous_keyframe_id, rp.x(), rp.y(), rp.z(), rq.w(), rq.x(), rq.y(), rq.z());
      for (int i = 0; i < 6; ++i) {
        for (int j = i; j < 6; ++j) file << "," << fmt::format("{}", (*k.relative_covariance)(i, j));
      }
    } else {
      file << std::string(8 + 21, ',');
    }
    file << "\n";
  }
  return file ? ok_status() : Status(Error(fmt::format("{}: write failed", path)));
}

Status write_innovations_csv(const std::string& path, const std::vector<pipeline::InnovationRecord>& records) {
  std::ofstream file(path);
  if (!file) return Error(fmt::format("{}: cannot write", path));
  file << "sensor,model,timestamp_ns,mahalanobis_squared,applied,innovation\n";
  for (const pipeline::InnovationRecord& r : records) {
    file << fmt::format("{},{},{},{},{},{}\n", r.sensor, r.model, r.timestamp.nanoseconds(), r.mahalanobis_squared, r.applied ? 1 : 0,
                        fmt::join(r.innovation, " "));
  }
  return file ? ok_status() : Status(Error(fmt::format("{}: write failed", path)));
}

nlohmann::json summary_json(const pipeline::SessionSummary& summary, double log_seconds) {
  nlohmann::json sensors = nlohmann::json::array();
  for (const pipeline::SensorStatistics& s : summary.sensors) {
    const double span = (s.last_time - s.first_time).seconds();
    sensors.push_back({{"name", s.name},
                       {"modality", config::to_string(s.modality)},
                       {"received", s.received},
                       {"fused", s.fused},
                       {"rolled_back", s.rolled_back},
                       {"rejected", pipeline::by_name(s.rejected)},
                       {"rate_hz", span > 0.0 ? static_cast<double>(s.received - 1) / span : 0.0},
                       {"timeouts", s.timeouts},
                       {"average_nis_per_dof", s.nis_count > 0 ? s.nis_sum / static_cast<double>(s.nis_count) : 0.0}});
  }
  nlohmann::json result = {{"filter", summary.filter},
                            {"poses", summary.poses},
                            {"keyframes", summary.keyframes},
                            {"rollbacks", summary.rollbacks},
                            {"zero_velocity_updates", summary.zero_velocity_updates},
                            {"final_state", msgs::to_string(summary.state)},
                            {"log_duration_s", log_seconds},
                            {"sensors", sensors}};
  if (summary.wheel_speed_scale) {
    result["wheel_speed_scale"] = {{"value", *summary.wheel_speed_scale}, {"sigma", summary.wheel_speed_scale_sigma}};
  }
  if (summary.gyro_yaw_scale) {
    result["gyro_yaw_scale"] = {{"value", *summary.gyro_yaw_scale}, {"sigma", summary.gyro_yaw_scale_sigma}};
  }
  if (summary.wheel_heading_drift) {
    result["wheel_heading_drift"] = {{"value", *summary.wheel_heading_drift}, {"sigma", summary.wheel_heading_drift_sigma}};
  }
  return result;
}

Result<std::vector<std::string>> write_plots(const std::string& out, const std::vector<msgs::PoseEstimate>& poses,
                                             const std::vector<pipeline::InnovationRecord>& innovations) {
  std::vector<std::string> written;
  if (poses.empty()) return written;
  const io::Trajectory trajectory = trajectory_of(poses);
  std::vector<double> times, sigmas;
  for (const msgs::PoseEstimate& pose : poses) {
    if (!times.empty() && (pose.timestamp - poses.front().timestamp).seconds() <= times.back()) continue;
    times.push_back((pose.timestamp - poses.front().timestamp).seconds());
    const msgs::Matrix6d covariance = pose.pose_covariance.value_or(msgs::Matrix6d::Zero());
    sigmas.push_back(std::sqrt(covariance(0, 0) + covariance(1, 1)));
  }
  const std::string trajectory_svg = (std::filesystem::path(out) / "trajectory.svg").string();
  HANZO_RETURN_IF_ERROR(eval::write_svg(trajectory_svg, eval::trajectory_top_view_svg(trajectory, trajectory, sigmas,
                                                                                      {"Estimated trajectory, coloured by horizontal position sigma",
                                                                                       "horizontal sigma (m)"})));
  written.push_back(trajectory_svg);
  const std::string covariance_svg = (std::filesystem::path(out) / "covariance.svg").string();
  HANZO_RETURN_IF_ERROR(eval::write_svg(covariance_svg, eval::error_over_time_svg(times, sigmas, eval::compute_statistics(sigmas),
                                                                                 {"Horizontal position sigma over time", "sigma (m)"})));
  written.push_back(covariance_svg);
  std::map<std::string, std::pair<std::vector<double>, std::vector<double>>> by_sensor;
  for (const pipeline::InnovationRecord& r : innovations) {
    auto& [t, nis] = by_sensor[r.sensor + "_" + std::string(r.model)];
    t.push_back((r.timestamp - poses.front().timestamp).seconds());
    nis.push_back(r.mahalanobis_squared);
  }
  for (const auto& [name, series] : by_sensor) {
    const std::string path = (std::filesystem::path(out) / fmt::format("innovations_{}.svg", name)).string();
    HANZO_RETURN_IF_ERROR(eval::write_svg(path, eval::error_over_time_svg(series.first, series.second, eval::compute_statistics(series.second),
                                                                         {fmt::format("Normalized innovation squared: {}", name), "NIS"})));
    written.push_back(path);
  }
  return written;
}

Result<nlohmann::json> evaluate(const std::string& ground_truth_path, const io::Trajectory& estimate) {
  io::Trajectory reference;
  HANZO_ASSIGN_OR_RETURN(reference, io::read_trajectory(ground_truth_path, io::TrajectoryFormat::kTum));
  eval::AssociatedTrajectories pairs;
  HANZO_ASSIGN_OR_RETURN(pairs, eval::associate(reference, estimate, eval::AssociationConfig{0.01, 0.0}));
  eval::ApeResult ape;
  HANZO_ASSIGN_OR_RETURN(ape, eval::compute_ape(pairs.reference, pairs.estimate));
  eval::ApeConfig aligned_config;
  aligned_config.alignment = eval::Alignment::kSE3;
  // Undefined for a straight-line trajectory (the alignment's rotation is not determined).
  const Result<eval::ApeResult> aligned = eval::compute_ape(pairs.reference, pairs.estimate, aligned_config);
  eval::RpeConfig rpe_config;
  rpe_config.delta = 1.0;
  rpe_config.delta_unit = eval::DeltaUnit::kMeters;
  eval::RpeResult rpe;
  HANZO_ASSIGN_OR_RETURN(rpe, eval::compute_rpe(pairs.reference, pairs.estimate, rpe_config));
  const double distance = pairs.reference.path_length();
  return nlohmann::json{{"pairs", ape.statistics.count},
                        {"distance_m", distance},
                        {"ape_rmse_m", ape.statistics.rmse},
                        {"ape_max_m", ape.statistics.max},
                        {"ape_se3_aligned_rmse_m", aligned ? nlohmann::json(aligned->statistics.rmse) : nlohmann::json()},
                        {"final_error_m", ape.errors.empty() ? 0.0 : ape.errors.back()},
                        {"rpe_1m_rmse_m", rpe.statistics.rmse}};
}

nlohmann::json mapping_json(const pipeline::MappingSummary& m) {
  return {{"scans_received", m.scans_received}, {"scans_registered", m.scans_registered},
          {"scans_refused", m.scans_refused},   {"degenerate_scans", m.degenerate_scans},
          {"weather_degraded_scans", m.weather_degraded_scans},
          {"map_keyframes", m.map_keyframes},   {"graph_keyframes", m.graph_keyframes},
          {"graph_landmarks", m.graph_landmarks}, {"graph_projections", m.graph_projections},
          {"loop_candidates", m.loop_candidates}, {"loop_closures", m.loop_closures},
          {"gnss_factors", m.gnss_factors},     {"map_memory_bytes", m.map_memory_bytes},
          {"wheel_slip_episodes", m.wheel_slip_episodes}, {"wheel_messages_withheld", m.wheel_messages_withheld},
          {"camera_frames_tracked", m.camera_frames_tracked}, {"camera_frames_lost", m.camera_frames_lost},
          {"visual_keyframes", m.visual_keyframes}, {"visual_landmarks", m.visual_landmarks},
          {"camera_standstill_frames", m.camera_standstill_frames}, {"visual_loop_closures", m.visual_loop_closures},
          {"visual_scale_free", m.visual_scale_free}, {"camera_dark_frames", m.camera_dark_frames},
          {"camera_glare_frames", m.camera_glare_frames}, {"camera_motion_blur_frames", m.camera_motion_blur_frames}};
}

// Each sensor's health at the end and its changes over the log (seconds from the log's start).
nlohmann::json health_json(const pipeline::Session& session, Timestamp log_start, Timestamp log_end) {
  const auto entry = [](const pipeline::SensorHealth& health) {
    return nlohmann::json{{"state", pipeline::to_string(health.state)}, {"reason", pipeline::to_string(health.reason)}};
  };
  nlohmann::json final_state = nlohmann::json::object();
  for (const pipeline::SensorHealth& health : session.health()) final_state[health.sensor] = entry(health);
  nlohmann::json changes = nlohmann::json::array();
  // Seconds each sensor spent in each state other than ok, by reason: "degraded:gated" -> s.
  std::map<std::string, std::map<std::string, double>> not_ok_seconds;
  const std::vector<pipeline::HealthChange>& all = session.health_changes();
  for (std::size_t i = 0; i < all.size(); ++i) {
    const pipeline::HealthChange& change = all[i];
    nlohmann::json item = entry(change.health);
    item["t_s"] = (change.time - log_start).seconds();
    item["sensor"] = change.health.sensor;
    changes.push_back(std::move(item));
    if (change.health.state == pipeline::HealthState::kOk) continue;
    Timestamp until = log_end;
    for (std::size_t j = i + 1; j < all.size(); ++j) {
      if (all[j].health.sensor == change.health.sensor) {
        until = all[j].time;
        break;
      }
    }
    const std::string key = fmt::format("{}:{}", pipeline::to_string(change.health.state), pipeline::to_string(change.health.reason));
    not_ok_seconds[change.health.sensor][key] += std::max(0.0, (until - change.time).seconds());
  }
  return {{"final", final_state}, {"changes", changes}, {"not_ok_seconds", not_ok_seconds}};
}

// The session's map as a FusionMap file with its occupancy and point images; the file names.
Result<std::vector<std::string>> write_map(const std::filesystem::path& out, const pipeline::Session& session, const RunOptions& options,
                                           Timestamp created) {
  msgs::FusionMap map = session.map();
  // A camera-only run has landmarks but no scans: no empty point or occupancy layers.
  if (map.occupancy && map.occupancy->occupancy.empty()) map.occupancy.reset();
  if (map.points && map.points->points.empty()) map.points.reset();
  map.map_id = "run";
  map.version = 1;
  map.created = created;  // the log's last pose: the same log gives the same file
  map.provenance.software_version = HANZO_FUSION_VERSION;
  HANZO_ASSIGN_OR_RETURN(map.sensor_configuration, read_file(options.config_path));
  msgs::InputLog input;
  HANZO_ASSIGN_OR_RETURN(input, maps::describe_input_file(options.log_path));
  map.provenance.input_logs.push_back(input);
  std::vector<std::string> written;
  const std::string fmap = (out / "map.fmap").string();
  HANZO_RETURN_IF_ERROR(maps::write_fusion_map(fmap, map));
  written.push_back(fmap);
  if (map.occupancy) {
    const std::string png = (out / "map.png").string();
    HANZO_RETURN_IF_ERROR(maps::write_occupancy_png(png, *map.occupancy));
    written.push_back(png);
  }
  if (map.points) {
    const std::string png = (out / "map_points.png").string();
    HANZO_RETURN_IF_ERROR(maps::write_points_png(png, *map.points));
    written.push_back(png);
  }
  return written;
}

int run(const Output& output, const RunOptions& options) {
  nlohmann::json result = {{"log", options.log_path}, {"out", options.out}};
  const auto fail = [&](const std::string& reason) { return report_failure(output, result, reason); };
  auto config = config::load_fusion_config(options.config_path);
  if (!config) return fail(config.error().message);
  calib::Calibration calibration;
  if (!options.calibration_path.empty()) {
    auto loaded = calib::load_calibration(options.calibration_path);
    if (!loaded) return fail(loaded.error().message);
    calibration = std::move(loaded).value();
  }
  for (const std::string& name : options.sensors) {
    if (config->find_sensor(name) == nullptr) return fail(fmt::format("--sensors: {} configures no sensor '{}'", options.config_path, name));
  }
  if (!options.sensors.empty()) {  // ablation: the others' messages are counted as unmapped
    std::erase_if(config->sensors, [&](const config::SensorConfig& sensor) {
      return std::find(options.sensors.begin(), options.sensors.end(), sensor.name) == options.sensors.end();
    });
  }
  pipeline::SessionConfig session_config = pipeline::SessionConfig::from(*config);
  session_config.mode = pipeline::SessionMode::kReplay;
  session_config.num_threads = options.threads;
  auto created = pipeline::Session::create(*config, calibration, session_config);
  if (!created) return fail(created.error().message);
  pipeline::Session& session = **created;
  auto reader = io::SensorLogReader::open(options.log_path);
  if (!reader) return fail(reader.error().message);
  std::error_code ec;
  std::filesystem::create_directories(options.out, ec);
  if (ec) return fail(fmt::format("{}: cannot create the output folder ({})", options.out, ec.message()));

  std::vector<msgs::PoseEstimate> poses;
  std::vector<pipeline::InnovationRecord> innovations;
  std::vector<msgs::Keyframe> keyframes;
  session.set_keyframe_callback([&keyframes](const msgs::Keyframe& keyframe) { keyframes.push_back(keyframe); });
  session.set_pose_callback([&poses](const msgs::PoseEstimate& pose) { poses.push_back(pose); });
  session.set_innovation_callback([&innovations](const pipeline::InnovationRecord& r) { innovations.push_back(r); });

  const auto& statistics = (*reader)->mcap().statistics();
  ProgressBar progress(Timestamp::from_nanoseconds(static_cast<int64_t>(statistics.message_start_time)),
                       Timestamp::from_nanoseconds(static_cast<int64_t>(statistics.message_end_time)));
  const pipeline::LogReplaySummary replay = pipeline::replay_log(session, **reader, [&progress](Timestamp time) { progress.update(time); });
  progress.finish();
  const uint64_t messages = replay.messages;
  const double fusion_seconds = replay.push_seconds;
  const Timestamp first = replay.first, last = replay.last;

  const pipeline::SessionSummary summary = session.summary();
  const pipeline::MappingSummary mapping = session.mapping_summary();
  const double log_seconds = (last - first).seconds();
  const io::Trajectory trajectory = trajectory_of(poses);
  const io::Trajectory optimized = trajectory_of(session.optimized_trajectory());
  const std::filesystem::path out(options.out);
  std::vector<std::string> files;
  const auto written = [&](const std::string& name, const Status& status) {
    if (status) files.push_back((out / name).string());
    return status;
  };
  for (const Status& status :
       {written("trajectory.tum", io::write_trajectory((out / "trajectory.tum").string(), trajectory, io::TrajectoryFormat::kTum)),
        written("trajectory_optimized.tum",
                io::write_trajectory((out / "trajectory_optimized.tum").string(), optimized, io::TrajectoryFormat::kTum)),
        written("poses.csv", write_poses_csv((out / "poses.csv").string(), poses)),
        written("innovations.csv", write_innovations_csv((out / "innovations.csv").string(), innovations)),
        written("keyframes.csv", write_keyframes_csv((out / "keyframes.csv").string(), keyframes, session))}) {
    if (!status) return fail(status.error().message);
  }
  if (mapping.map_keyframes > 0 || mapping.visual_keyframes > 0) {
    auto map_files = write_map(out, session, options, poses.empty() ? last : poses.back().timestamp);
    if (!map_files) return fail(map_files.error().message);
    files.insert(files.end(), map_files->begin(), map_files->end());
  }
  auto plots = write_plots(options.out, poses, innovations);
  if (!plots) return fail(plots.error().message);

  result["ok"] = true;
  result["mode"] = pipeline::to_string(session.mode());
  result["summary"] = summary_json(summary, log_seconds);
  result["mapping"] = mapping_json(mapping);
  result["health"] = health_json(session, first, last);
  result["timing"] = {{"messages", messages},
                      {"threads", options.threads},
                      {"fusion_seconds", fusion_seconds},
                      {"microseconds_per_message", messages > 0 ? 1e6 * fusion_seconds / static_cast<double>(messages) : 0.0},
                      {"realtime_factor", fusion_seconds > 0.0 ? log_seconds / fusion_seconds : 0.0}};
  result["unread_messages"] = replay.unread;
  result["unmapped_topics"] = replay.unmapped_topics;
  if (!poses.empty()) {
    const msgs::PoseEstimate& final_pose = poses.back();
    result["final_pose"] = {{"timestamp_ns", final_pose.timestamp.nanoseconds()},
                            {"position", {final_pose.T_world_body.position.x(), final_pose.T_world_body.position.y(),
                                          final_pose.T_world_body.position.z()}},
                            {"state", msgs::to_string(final_pose.status.state)}};
  }
  result["files"] = files;
  result["plots"] = *plots;
  // An evaluation that cannot be computed is reported as undefined with the reason; the
  // outputs above are written either way.
  const auto score = [&](const char* key, const io::Trajectory& estimate) {
    auto evaluation = evaluate(options.ground_truth, estimate);
    result[key] = evaluation ? *evaluation : nlohmann::json{{"undefined", evaluation.error().message}};
  };
  if (!options.ground_truth.empty()) {
    score("evaluation", trajectory);
    score("evaluation_optimized", optimized);
  }
  std::ofstream((out / "summary.json").string()) << result.dump(2) << "\n";

  std::string text = fmt::format("{} poses from {} messages ({:.1f} s of log) in {:.3f} s: {:.0f}x real time\n", summary.poses, messages,
                                 log_seconds, fusion_seconds, fusion_seconds > 0.0 ? log_seconds / fusion_seconds : 0.0);
  for (const pipeline::SensorStatistics& s : summary.sensors) {
    text += fmt::format("  {:<12} received {:>7}  fused {:>7}  rolled back {:>4}  rejected {:>5}", s.name, s.received, s.fused,
                        s.rolled_back, s.rejected_total());
    for (const auto& [reason, count] : s.rejected) text += fmt::format("  {}={}", pipeline::to_string(reason), count);
    text += "\n";
  }
  if (mapping.graph_keyframes > 0) {
    text += fmt::format("graph: {} keyframes, {} GNSS factors, {} loop closures", mapping.graph_keyframes, mapping.gnss_factors,
                        mapping.loop_closures);
    if (mapping.graph_landmarks > 0) {
      text += fmt::format("; visual-inertial: {} landmarks, {} projections", mapping.graph_landmarks, mapping.graph_projections);
    }
    if (mapping.scans_received > 0) {
      text += fmt::format("; map: {} keyframes from {} of {} sweeps registered", mapping.map_keyframes, mapping.scans_registered,
                          mapping.scans_received);
    }
    if (mapping.wheel_slip_episodes > 0) {
      text += fmt::format("; wheels slipped {} times ({} messages not fused)", mapping.wheel_slip_episodes, mapping.wheel_messages_withheld);
    }
    text += "\n";
  }
  if (mapping.camera_frames_tracked + mapping.camera_frames_lost > 0) {
    text += fmt::format("visual odometry: {} frames tracked, {} lost, {} standing still; {} keyframes, {} landmarks, {} loops closed{}\n",
                        mapping.camera_frames_tracked, mapping.camera_frames_lost, mapping.camera_standstill_frames, mapping.visual_keyframes,
                        mapping.visual_landmarks, mapping.visual_loop_closures,
                        mapping.visual_scale_free ? " (monocular: lengths in units of its first baseline)" : "");
    if (mapping.camera_dark_frames + mapping.camera_glare_frames + mapping.camera_motion_blur_frames > 0) {
      text += fmt::format("  images: {} dark, {} with glare, {} blurred by motion\n", mapping.camera_dark_frames, mapping.camera_glare_frames,
                          mapping.camera_motion_blur_frames);
    }
  }
  for (const auto& [sensor, states] : result["health"]["not_ok_seconds"].items()) {
    text += fmt::format("  {:<12} not ok for", sensor);
    for (const auto& [state, seconds] : states.items()) text += fmt::format("  {:.1f} s {}", seconds.get<double>(), state);
    text += "\n";
  }
  if (!poses.empty()) {
    const auto& p = poses.back().T_world_body.position;
    text += fmt::format("final position ({:.4f}, {:.4f}, {:.4f}) m, state {}\n", p.x(), p.y(), p.z(), msgs::to_string(summary.state));
  }
  if (summary.wheel_speed_scale) {
    text += fmt::format("wheel speed scale {:.4f} +- {:.4f} (the wheels read {:+.2f} % of the distance driven)\n", *summary.wheel_speed_scale,
                        summary.wheel_speed_scale_sigma, 100.0 * (*summary.wheel_speed_scale - 1.0));
  }
  if (summary.gyro_yaw_scale) {
    text += fmt::format("gyro yaw-rate scale {:.4f} +- {:.4f} (the gyro reads turns {:+.2f} % off)\n", *summary.gyro_yaw_scale,
                        summary.gyro_yaw_scale_sigma, 100.0 * (*summary.gyro_yaw_scale - 1.0));
  }
  if (summary.wheel_heading_drift) {
    text += fmt::format("wheel heading drift {:.5f} +- {:.5f} rad/m (the wheels turn {:.2f} deg per 100 m driven straight)\n",
                        *summary.wheel_heading_drift, summary.wheel_heading_drift_sigma, *summary.wheel_heading_drift * 100.0 * 180.0 / M_PI);
  }
  for (const auto& [key, label] : {std::pair<const char*, const char*>{"evaluation", "real-time"}, {"evaluation_optimized", "optimized"}}) {
    if (!result.contains(key)) continue;
    const auto& e = result[key];
    if (e.contains("undefined")) {
      text += fmt::format("{}: APE undefined ({})\n", label, e["undefined"].get<std::string>());
      continue;
    }
    const std::string aligned = e["ape_se3_aligned_rmse_m"].is_null() ? "undefined" : fmt::format("{:.3f}", e["ape_se3_aligned_rmse_m"].get<double>());
    text += fmt::format("{}: APE rmse {:.3f} m (max {:.3f}; SE3-aligned {}) over {:.1f} m; RPE (1 m) rmse {:.3f} m\n", label,
                        e["ape_rmse_m"].get<double>(), e["ape_max_m"].get<double>(), aligned, e["distance_m"].get<double>(),
                        e["rpe_1m_rmse_m"].get<double>());
  }
  text += fmt::format("wrote {} files and {} plots into {}\n", files.size() + 1, plots->size(), options.out);
  return report_success(output, result, text);
}

}  // namespace

void add_run_command(CLI::App& app, const Output& output, Command& run_command) {
  auto options = std::make_shared<RunOptions>();
  CLI::App* command = app.add_subcommand("run", "Replay a sensor log through the whole pipeline (filter, LiDAR odometry, graph, map)");
  command->add_option("--config", options->config_path, "Fusion configuration YAML")->required();
  command->add_option("--calibration,--calib", options->calibration_path, "Calibration YAML (default: every sensor at the body origin)");
  command->add_option("--log", options->log_path, "Sensor log (.mcap)")->required();
  command->add_option("--out", options->out, "Output folder")->required();
  command->add_option("--ground-truth,--gt", options->ground_truth, "Ground-truth trajectory (TUM) for APE / RPE");
  command->add_option("--threads", options->threads, "LiDAR odometry threads (0: all cores); the output does not depend on it")
      ->capture_default_str();
  command->add_option("--sensors", options->sensors, "Fuse only these configured sensors (comma-separated names), e.g. for an ablation")
      ->delimiter(',');
  command->callback([&output, &run_command, options] { run_command = [&output, options] { return run(output, *options); }; });
}

}  // namespace hanzo::fusion::app
