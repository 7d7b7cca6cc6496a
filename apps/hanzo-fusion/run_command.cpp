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
#include <iostream>
#include <iterator>
#include <cstdlib>
#include <map>
#include <optional>
#include <set>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "commands.hpp"
#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/logging.hpp"
#include "hanzo/fusion/eval/association.hpp"
#include "hanzo/fusion/eval/plots.hpp"
#include "hanzo/fusion/eval/pose_error.hpp"
#include "hanzo/fusion/eval/statistics.hpp"
#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/io/trajectory.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/maps/map_export.hpp"
#include "hanzo/fusion/maps/splat_ply.hpp"
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
  std::optional<double> ground_truth_time_offset;  // s added to the estimate's times to pair them with the ground truth's
  int threads = 1;
  std::vector<std::string> sensors;  // empty: every configured sensor
  bool allow_partial = false;        // a corrupted or truncated log still exits 0
};

// "1 keyframe", "2 keyframes".
std::string count_of(uint64_t count, std::string_view thing) { return fmt::format("{} {}{}", count, thing, count == 1 ? "" : "s"); }

// Cameras whose calibration entry has no intrinsics take those of their first image in the log
// that carries them (the ones a ROS camera_info or an importer stored); the names of the cameras
// so completed. A camera left without intrinsics is refused later, by name.
Result<std::vector<std::string>> intrinsics_from_images(const config::FusionConfig& config, calib::Calibration& calibration,
                                                        const std::string& log_path) {
  std::vector<std::string> completed;
  for (const config::SensorConfig& sensor : config.sensors) {
    if (sensor.modality != config::SensorModality::kCamera) continue;
    auto entry = std::find_if(calibration.sensors.begin(), calibration.sensors.end(),
                              [&](const calib::SensorCalibration& s) { return s.sensor == sensor.name; });
    if (entry != calibration.sensors.end() && entry->camera) continue;
    io::mcap::ReadOptions only_this;
    only_this.topics = {sensor.topic};
    std::unique_ptr<io::SensorLogReader> reader;
    HANZO_ASSIGN_OR_RETURN(reader, io::SensorLogReader::open(log_path, only_this));
    io::LogEntry image_entry;
    constexpr int kImagesLookedAt = 100;
    for (int looked = 0; looked < kImagesLookedAt; ++looked) {
      const Result<bool> more = reader->next(image_entry);
      if (more && !*more) break;
      const auto* message = more ? std::get_if<msgs::SensorMessage>(&image_entry.message) : nullptr;
      const auto* image = message != nullptr ? std::get_if<msgs::ImageMessage>(message) : nullptr;
      if (image == nullptr || !image->intrinsics) continue;
      calib::CameraCalibration camera{*image->intrinsics, image->distortion.value_or(msgs::DistortionModel{})};
      if (camera.intrinsics.width == 0 || camera.intrinsics.height == 0) {
        camera.intrinsics.width = image->width;
        camera.intrinsics.height = image->height;
      }
      if (entry == calibration.sensors.end()) {
        calibration.sensors.push_back(calib::SensorCalibration{});
        calibration.sensors.back().sensor = sensor.name;
        entry = std::prev(calibration.sensors.end());
      }
      entry->camera = std::move(camera);
      completed.push_back(sensor.name);
      break;
    }
  }
  return completed;
}

// Fails when no configured sensor's topic is in the log (nothing would be fused); warns for
// each configured sensor whose topic is missing.
Status check_topics(const config::FusionConfig& config, const io::mcap::McapReader& log, const std::string& log_path,
                    nlohmann::json& result) {
  std::set<std::string> log_topics;
  for (const auto& [id, channel] : log.channels()) {
    if (channel.metadata.count("mirror_of") == 0) log_topics.insert(channel.topic);  // not the Foxglove mirrors
  }
  std::vector<std::string> configured, missing;
  for (const config::SensorConfig& sensor : config.sensors) {
    configured.push_back(sensor.topic);
    if (log_topics.count(sensor.topic) == 0) missing.push_back(fmt::format("{} ({})", sensor.name, sensor.topic));
  }
  if (!config.sensors.empty() && missing.size() == config.sensors.size()) {
    if (log.warning()) return Error(fmt::format("partial log: {}: none of the configured sensors' topics could be read", *log.warning()));
    return Error(fmt::format("{} has none of the configured sensors' topics ({}); its topics: {}", log_path, fmt::join(configured, ", "),
                             log_topics.empty() ? "none" : fmt::format("{}", fmt::join(log_topics, ", "))));
  }
  result["sensors_without_messages"] = missing;
  for (const std::string& sensor : missing) logger()->warn("{}: no messages for configured sensor {}", log_path, sensor);
  return ok_status();
}

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

using app::trajectory_of;  // the PoseEstimate overload (commands.hpp) beside this one

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

// How the estimate's times are paired with the ground truth's: the given offset; or, for a log
// whose importer put relative times (a dataset's times from 0) at an origin (`import` metadata
// relative_time_origin_s) and a ground truth in relative times, that origin taken off; or as
// they are.
struct TimePairing {
  double estimate_time_offset_s = 0.0;
  std::string description = "times as they are";
};

TimePairing time_pairing(const RunOptions& options, const io::mcap::McapReader& log, const io::Trajectory& reference) {
  if (options.ground_truth_time_offset) {
    return {*options.ground_truth_time_offset, fmt::format("estimate times {:+.9g} s (--gt-time-offset)", *options.ground_truth_time_offset)};
  }
  for (const io::mcap::Metadata& metadata : log.metadata()) {
    const auto origin = metadata.values.find("relative_time_origin_s");
    if (metadata.name != "import" || origin == metadata.values.end() || reference.empty()) continue;
    const double origin_s = std::strtod(origin->second.c_str(), nullptr);
    if (reference.timestamps.front().seconds() < eval::kRelativeTimesBelow_s && origin_s >= eval::kRelativeTimesBelow_s) {
      return {-origin_s, fmt::format("the log's relative times start at {} s (its importer's origin) and the ground truth's at 0: "
                                     "paired with the origin taken off",
                                     origin->second)};
    }
  }
  return {};
}

Result<nlohmann::json> evaluate(const std::string& ground_truth_path, const io::Trajectory& estimate, const RunOptions& options,
                                const io::mcap::McapReader& log) {
  io::Trajectory reference;
  HANZO_ASSIGN_OR_RETURN(reference, io::read_trajectory(ground_truth_path, io::TrajectoryFormat::kTum));
  const TimePairing pairing = time_pairing(options, log, reference);
  eval::AssociatedTrajectories pairs;
  HANZO_ASSIGN_OR_RETURN(pairs, with_context(eval::associate(reference, estimate, eval::AssociationConfig{0.01, pairing.estimate_time_offset_s}),
                                             pairing.description));
  eval::ApeResult ape;
  HANZO_ASSIGN_OR_RETURN(ape, eval::compute_ape(pairs.reference, pairs.estimate));
  eval::ApeConfig aligned_config;
  aligned_config.alignment = eval::Alignment::kSE3;
  // Undefined for a straight-line trajectory (the alignment's rotation is not determined).
  const Result<eval::ApeResult> aligned = eval::compute_ape(pairs.reference, pairs.estimate, aligned_config);
  eval::ApeConfig yaw_config;
  yaw_config.alignment = eval::Alignment::kYaw;  // roll and pitch are observable wherever an IMU measures gravity
  const Result<eval::ApeResult> yaw_aligned = eval::compute_ape(pairs.reference, pairs.estimate, yaw_config);
  eval::ApeConfig similarity_config;
  similarity_config.alignment = eval::Alignment::kSim3;  // a monocular camera's trajectory has no metric scale
  const Result<eval::ApeResult> similar = eval::compute_ape(pairs.reference, pairs.estimate, similarity_config);
  eval::RpeConfig rpe_config;
  rpe_config.delta = 1.0;
  rpe_config.delta_unit = eval::DeltaUnit::kMeters;
  eval::RpeResult rpe;
  HANZO_ASSIGN_OR_RETURN(rpe, eval::compute_rpe(pairs.reference, pairs.estimate, rpe_config));
  const double distance = pairs.reference.path_length();
  return nlohmann::json{{"pairs", ape.statistics.count},
                        {"time_pairing", pairing.description},
                        {"estimate_time_offset_s", pairing.estimate_time_offset_s},
                        {"distance_m", distance},
                        {"ape_rmse_m", ape.statistics.rmse},
                        {"ape_max_m", ape.statistics.max},
                        {"ape_se3_aligned_rmse_m", aligned ? nlohmann::json(aligned->statistics.rmse) : nlohmann::json()},
                        {"ape_yaw_aligned_rmse_m", yaw_aligned ? nlohmann::json(yaw_aligned->statistics.rmse) : nlohmann::json()},
                        {"ape_sim3_aligned_rmse_m", similar ? nlohmann::json(similar->statistics.rmse) : nlohmann::json()},
                        {"final_error_m", ape.errors.empty() ? 0.0 : ape.errors.back()},
                        {"rpe_1m_rmse_m", rpe.statistics.rmse}};
}

nlohmann::json mapping_json(const pipeline::MappingSummary& m) {
  return {{"scans_received", m.scans_received}, {"scans_registered", m.scans_registered},
          {"scans_refused", m.scans_refused},   {"degenerate_scans", m.degenerate_scans},
          {"weather_degraded_scans", m.weather_degraded_scans},
          {"map_keyframes", m.map_keyframes},   {"map_revisits", m.map_revisits}, {"graph_keyframes", m.graph_keyframes},
          {"graph_landmarks", m.graph_landmarks}, {"graph_projections", m.graph_projections},
          {"graph_imu_factors", m.graph_imu_factors}, {"graph_lidar_factors", m.graph_lidar_factors},
          {"splat_views", m.splat_views}, {"splat_iterations", m.splat_iterations}, {"splat_gaussians", m.splat_gaussians},
          {"splat_images_skipped", m.splat_images_skipped},
          {"loop_candidates", m.loop_candidates}, {"loop_closures", m.loop_closures},
          {"gnss_factors", m.gnss_factors},     {"graph_velocity_factors", m.graph_velocity_factors},
          {"map_memory_bytes", m.map_memory_bytes},
          {"wheel_slip_episodes", m.wheel_slip_episodes}, {"wheel_messages_withheld", m.wheel_messages_withheld},
          {"camera_frames_tracked", m.camera_frames_tracked}, {"camera_frames_lost", m.camera_frames_lost},
          {"visual_keyframes", m.visual_keyframes}, {"visual_landmarks", m.visual_landmarks},
          {"camera_standstill_frames", m.camera_standstill_frames}, {"visual_loop_closures", m.visual_loop_closures},
          {"visual_scale_free", m.visual_scale_free}, {"camera_dark_frames", m.camera_dark_frames},
          {"camera_glare_frames", m.camera_glare_frames}, {"camera_motion_blur_frames", m.camera_motion_blur_frames},
          {"camera_features", m.camera_features}, {"camera_feature_ms", m.camera_feature_ms}, {"camera_mapping_ms", m.camera_mapping_ms},
          {"camera_learned_matcher", m.camera_learned_matcher}, {"visual_place_recognition", m.visual_place_recognition},
          {"detections_received", m.detections_received}, {"detections_computed", m.detections_computed},
          {"detector_failures", m.detector_failures}, {"detector_ms", m.detector_ms}, {"detections_refused", m.detections_refused},
          {"detections_matched", m.detections_matched}, {"detections_late", m.detections_late},
          {"images_without_detections", m.images_without_detections}, {"images_masked", m.images_masked},
          {"dynamic_objects_masked", m.dynamic_objects_masked}, {"masked_image_share", m.masked_image_share},
          {"lidar_points_labelled", m.lidar_points_labelled}, {"lidar_points_masked", m.lidar_points_masked},
          {"map_points_moving_removed", m.map_points_moving_removed}};
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
  msgs::FusionMap map;
  HANZO_ASSIGN_OR_RETURN(map, pipeline::replayed_map(session, "run", created, options.config_path, options.log_path, HANZO_FUSION_VERSION));
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
  if (map.gaussian_splats) {  // fusion.mapping.splats: the PLY 3DGS viewers open
    const std::string ply = (out / "splats.ply").string();
    HANZO_RETURN_IF_ERROR(write_file_durably(ply, maps::encode_splat_ply(*map.gaussian_splats)));
    written.push_back(ply);
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
  auto reader = io::SensorLogReader::open(options.log_path);
  if (!reader) return fail(reader.error().message);
  if (Status topics = check_topics(*config, (*reader)->mcap(), options.log_path, result); !topics) return fail(topics.error().message);
  // Without a calibration every sensor is at the body origin; cameras may still take their
  // intrinsics from the images (they then need entries of their own, identity for the others).
  const bool calibrated = !calibration.sensors.empty();
  auto completed = intrinsics_from_images(*config, calibration, options.log_path);
  if (!completed) return fail(completed.error().message);
  if (!calibrated && !completed->empty()) {
    for (const config::SensorConfig& sensor : config->sensors) {
      if (calibration.find(sensor.name) != nullptr) continue;
      calibration.sensors.push_back(calib::SensorCalibration{});
      calibration.sensors.back().sensor = sensor.name;
    }
    logger()->warn("no calibration: every sensor is mounted at the body origin with no time offset");
  }
  for (const std::string& camera : *completed) logger()->info("camera '{}': intrinsics from its images in {}", camera, options.log_path);
  result["intrinsics_from_images"] = *completed;
  pipeline::SessionConfig session_config = pipeline::SessionConfig::from(*config);
  session_config.mode = pipeline::SessionMode::kReplay;
  session_config.num_threads = options.threads;
  auto created = pipeline::Session::create(*config, calibration, session_config);
  if (!created) return fail(created.error().message);
  pipeline::Session& session = **created;
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

  // A log read only in part (corrupted chunks, a truncated file, messages that do not decode)
  // gives outputs for what was read, and fails unless --allow-partial.
  const std::string incomplete = replay.incomplete();
  result["ok"] = incomplete.empty() || options.allow_partial;
  result["partial"] = !incomplete.empty();
  if (!incomplete.empty()) result["incomplete"] = incomplete;
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
    auto evaluation = evaluate(options.ground_truth, estimate, options, (*reader)->mcap());
    result[key] = evaluation ? *evaluation : nlohmann::json{{"undefined", evaluation.error().message}};
  };
  if (!options.ground_truth.empty()) {
    score("evaluation", trajectory);
    score("evaluation_optimized", optimized);
    // The real-time poses the session claims (every state but INITIALIZING: before GNSS has
    // given the heading, a world pose is a guess the state says is one).
    std::vector<msgs::PoseEstimate> claimed;
    std::copy_if(poses.begin(), poses.end(), std::back_inserter(claimed),
                 [](const msgs::PoseEstimate& pose) { return pose.status.state != msgs::TrackingState::kInitializing; });
    score("evaluation_tracking", trajectory_of(claimed));
    result["evaluation_tracking"]["poses_initializing_left_out"] = poses.size() - claimed.size();
  }
  std::ofstream((out / "summary.json").string()) << result.dump(2) << "\n";

  const double realtime_factor = fusion_seconds > 0.0 ? log_seconds / fusion_seconds : 0.0;
  std::string text = fmt::format("{} poses from {} messages ({:.1f} s of log) in {:.3f} s: {}x real time\n", summary.poses, messages,
                                 log_seconds, fusion_seconds,
                                 realtime_factor < 10.0 ? fmt::format("{:.2f}", realtime_factor) : fmt::format("{:.0f}", realtime_factor));
  for (const pipeline::SensorStatistics& s : summary.sensors) {
    text += fmt::format("  {:<12} received {:>7}  fused {:>7}  rolled back {:>4}  rejected {:>5}", s.name, s.received, s.fused,
                        s.rolled_back, s.rejected_total());
    for (const auto& [reason, count] : s.rejected) text += fmt::format("  {}={}", pipeline::to_string(reason), count);
    text += "\n";
  }
  if (mapping.graph_keyframes > 0) {
    text += fmt::format("graph: {}, {}, {}", count_of(mapping.graph_keyframes, "keyframe"), count_of(mapping.gnss_factors, "GNSS factor"),
                        count_of(mapping.loop_closures, "loop closure"));
    if (mapping.graph_landmarks > 0) {
      text += fmt::format("; visual-inertial: {} landmarks, {} projections", mapping.graph_landmarks, mapping.graph_projections);
    }
    if (mapping.graph_lidar_factors > 0) {
      text += fmt::format("; LiDAR-inertial: {} IMU and {} LiDAR links", mapping.graph_imu_factors, mapping.graph_lidar_factors);
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
  if (mapping.splat_views > 0) {
    text += fmt::format("splats: {} Gaussians from {} after {} steps\n", mapping.splat_gaussians, count_of(mapping.splat_views, "view"),
                        mapping.splat_iterations);
  }
  if (mapping.camera_frames_tracked + mapping.camera_frames_lost > 0) {
    // The visual-inertial odometry keeps its landmarks in the graph (counted on the graph's line).
    const bool own_map = mapping.visual_keyframes + mapping.visual_landmarks > 0 || mapping.graph_landmarks == 0;
    text += fmt::format("visual odometry: {} tracked, {} lost, {} standing still{}{}\n", count_of(mapping.camera_frames_tracked, "frame"),
                        mapping.camera_frames_lost, mapping.camera_standstill_frames,
                        own_map ? fmt::format("; {}, {}, {} closed", count_of(mapping.visual_keyframes, "keyframe"),
                                              count_of(mapping.visual_landmarks, "landmark"), count_of(mapping.visual_loop_closures, "loop"))
                                : "",
                        mapping.visual_scale_free ? " (monocular: lengths in units of its first baseline)" : "");
    text += fmt::format("  features: {}, {:.1f} ms per frame{}{}{}\n", mapping.camera_features, mapping.camera_feature_ms,
                        mapping.camera_mapping_ms > 0.0 ? fmt::format("; local mapping {:.1f} ms per keyframe", mapping.camera_mapping_ms) : "",
                        mapping.camera_learned_matcher ? "; first views matched through the learned correspondence filter" : "",
                        mapping.visual_place_recognition == "learned" ? "; loop candidates by learned place recognition (VLAD)"
                        : mapping.visual_place_recognition.empty() && mapping.visual_keyframes > 0 ? "; no loop closure"
                                                                                                    : "");
    if (mapping.detections_received > 0) {
      text += fmt::format("  detections: {} received, {} matched to their image, {} late, {} refused; {} images waited in vain; {} images masked "
                          "({} moving objects, {:.1f} % of a masked image)\n",
                          mapping.detections_received, mapping.detections_matched, mapping.detections_late, mapping.detections_refused,
                          mapping.images_without_detections, mapping.images_masked, mapping.dynamic_objects_masked, 100.0 * mapping.masked_image_share);
    }
    if (mapping.detections_computed > 0) {
      text += fmt::format("  object detector: {} images ({} failed), {:.1f} ms per image\n", mapping.detections_computed, mapping.detector_failures,
                          mapping.detector_ms);
    }
    if (mapping.camera_dark_frames + mapping.camera_glare_frames + mapping.camera_motion_blur_frames > 0) {
      text += fmt::format("  images: {} dark, {} with glare, {} blurred by motion\n", mapping.camera_dark_frames, mapping.camera_glare_frames,
                          mapping.camera_motion_blur_frames);
    }
  }
  if (mapping.lidar_points_labelled + mapping.lidar_points_masked > 0) {
    text += fmt::format("camera outputs onto the LiDAR: {} points took a segmentation class, {} on moving objects left out of the map\n",
                        mapping.lidar_points_labelled, mapping.lidar_points_masked);
  }
  if (mapping.map_points_moving_removed > 0) {
    text += fmt::format("moving objects: {} map points left out (later or earlier scans saw through their place)\n", mapping.map_points_moving_removed);
  }
  for (const auto& [sensor, states] : result["health"]["not_ok_seconds"].items()) {
    text += fmt::format("  {:<12} not ok for", sensor);
    for (const auto& [state, seconds] : states.items()) text += fmt::format("  {:.1f} s {}", seconds.get<double>(), state);
    text += "\n";
  }
  if (!poses.empty()) {
    const auto& p = poses.back().T_world_body.position;
    // Why a run whose sensors are all healthy ends DEGRADED: the spec calls localization
    // reliable only with two or more modalities constraining it.
    const msgs::PoseStatus& status = poses.back().status;
    const std::string why = summary.state == msgs::TrackingState::kDegraded && !status.localization_reliable()
                                ? fmt::format(" ({} modality active: reliable localization takes two or more)", status.active_modalities)
                                : "";
    text += fmt::format("final position ({:.4f}, {:.4f}, {:.4f}) m, state {}{}\n", p.x(), p.y(), p.z(), msgs::to_string(summary.state), why);
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
  for (const auto& [key, label] : {std::pair<const char*, const char*>{"evaluation", "real-time"},
                                   {"evaluation_tracking", "real-time once tracking"},
                                   {"evaluation_optimized", "optimized"}}) {
    if (!result.contains(key)) continue;
    const auto& e = result[key];
    if (e.contains("undefined")) {
      text += fmt::format("{}: APE undefined ({})\n", label, e["undefined"].get<std::string>());
      continue;
    }
    if (e["time_pairing"] != "times as they are") text += fmt::format("{}: times paired so: {}\n", label, e["time_pairing"].get<std::string>());
    // The SE3-aligned figure leads: the run's world (the first GNSS fix, or where the body
    // started) need not be the ground truth's, so the unaligned one measures both frames' offset
    // as well as the error unless they share a datum.
    // A monocular run's lengths are in units of its first baseline: Sim3 (scale too) leads.
    const char* aligned_key = mapping.visual_scale_free ? "ape_sim3_aligned_rmse_m" : "ape_se3_aligned_rmse_m";
    const std::string aligned = e[aligned_key].is_null() ? "undefined (a straight path leaves the alignment's rotation free)"
                                                         : fmt::format("{:.3f} m", e[aligned_key].get<double>());
    text += fmt::format("{}: APE rmse ({}-aligned) {} over {:.1f} m; in the run's world frame {:.3f} m (max {:.3f}; meaningful when it "
                        "shares the ground truth's datum); RPE (1 m) rmse {:.3f} m\n",
                        label, mapping.visual_scale_free ? "Sim3" : "SE3", aligned, e["distance_m"].get<double>(), e["ape_rmse_m"].get<double>(),
                        e["ape_max_m"].get<double>(), e["rpe_1m_rmse_m"].get<double>());
  }
  text += fmt::format("wrote {} files and {} plots into {}\n", files.size() + 1, plots->size(), options.out);
  if (!incomplete.empty()) {
    if (options.allow_partial) return report_success(output, result, text + fmt::format("warning: partial log: {}\n", incomplete));
    if (!output.json) std::cout << text;
    return fail(fmt::format("partial log: {} (outputs written for what was read; --allow-partial accepts it)", incomplete));
  }
  return report_success(output, result, text);
}

}  // namespace

io::Trajectory trajectory_of(const std::vector<msgs::PoseEstimate>& poses) {
  io::Trajectory trajectory;
  for (const msgs::PoseEstimate& pose : poses) {
    if (!trajectory.timestamps.empty() && pose.timestamp <= trajectory.timestamps.back()) continue;
    trajectory.timestamps.push_back(pose.timestamp);
    trajectory.poses.push_back(pose.T_world_body.to_se3().matrix());
  }
  return trajectory;
}

void add_run_command(CLI::App& app, const Output& output, Command& run_command) {
  auto options = std::make_shared<RunOptions>();
  CLI::App* command = app.add_subcommand("run", "Replay a sensor log through the whole pipeline (filter, LiDAR odometry, graph, map)");
  command->add_option("--config", options->config_path, "Fusion configuration YAML")->required();
  command->add_option("--calibration,--calib", options->calibration_path, "Calibration YAML (default: every sensor at the body origin)");
  command->add_option("--log", options->log_path, "Sensor log (.mcap)")->required();
  command->add_option("--out", options->out, "Output folder")->required();
  command->add_option("--ground-truth,--gt", options->ground_truth, "Ground-truth trajectory (TUM) for APE / RPE");
  command->add_option("--gt-time-offset", options->ground_truth_time_offset,
                      "Seconds added to the estimate's times to pair them with the ground truth's (default: 0, or the importer's "
                      "relative-time origin taken off when the ground truth's times are relative)");
  command->add_option("--threads", options->threads, "LiDAR odometry threads (0: all cores); the output does not depend on it")
      ->capture_default_str();
  command->add_flag("--allow-partial", options->allow_partial,
                    "Exit 0 for a log read only in part (corrupted chunks, truncated file, undecodable messages); the summary says what was lost");
  command->add_option("--sensors", options->sensors, "Fuse only these configured sensors (comma-separated names), e.g. for an ablation")
      ->delimiter(',');
  command->callback([&output, &run_command, options] { run_command = [&output, options] { return run(output, *options); }; });
}

}  // namespace hanzo::fusion::app
