// Python bindings of pipeline::Session (pipeline/session.hpp), the whole pipeline every face
// runs: messages pushed from numpy arrays and numbers (times in seconds since the epoch, SI
// units), or a whole sensor log replayed; poses, the optimized trajectory and the map read back
// as numpy arrays. Replay mode: the same input gives the same output. Bad input (wrong shapes,
// NaN, unknown sensors...) is not fused: push_* return the rejection ("reason: detail"), None
// when the message was accepted; construction errors raise ValueError.

#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "hanzo/fusion/io/sensor_log.hpp"
#include "hanzo/fusion/maps/fusion_map_file.hpp"
#include "hanzo/fusion/pipeline/log_replay.hpp"
#include "hanzo/fusion/pipeline/session.hpp"
#include "hanzo/fusion/pipeline/session_merge.hpp"
#include "message_conversion.hpp"

namespace py = pybind11;
using namespace hanzo::fusion;

namespace {

using PointRows = Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>;
using PoseRows = Eigen::Matrix<double, Eigen::Dynamic, 8, Eigen::RowMajor>;

Timestamp time_from(double time_s) {
  if (!std::isfinite(time_s) || time_s <= 0) throw py::value_error(fmt::format("time_s: expected a positive finite number, got {}", time_s));
  return Timestamp::from_seconds(time_s);
}

// One row (t, x, y, z, qw, qx, qy, qz) per pose.
PoseRows pose_rows(const std::vector<pipeline::StampedPose>& poses) {
  PoseRows rows(static_cast<Eigen::Index>(poses.size()), 8);
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const Eigen::Vector3d t = poses[i].T_world_body.translation();
    const Eigen::Quaterniond& q = poses[i].T_world_body.rotation().quaternion();
    rows.row(static_cast<Eigen::Index>(i)) << poses[i].timestamp.seconds(), t.x(), t.y(), t.z(), q.w(), q.x(), q.y(), q.z();
  }
  return rows;
}

class PySession {
 public:
  PySession(const std::string& config_path, const std::optional<std::string>& calibration_path, int threads) : config_path_(config_path) {
    Result<config::FusionConfig> config = config::load_fusion_config(config_path);
    if (!config) throw py::value_error(config.error().message);
    calib::Calibration calibration;
    if (calibration_path) {
      Result<calib::Calibration> loaded = calib::load_calibration(*calibration_path);
      if (!loaded) throw py::value_error(loaded.error().message);
      calibration = std::move(*loaded);
    }
    pipeline::SessionConfig session_config = pipeline::SessionConfig::from(*config);
    session_config.num_threads = threads;
    Result<std::unique_ptr<pipeline::Session>> created = pipeline::Session::create(*config, calibration, session_config);
    if (!created) throw py::value_error(created.error().message);
    session_ = std::move(*created);
    session_->set_pose_callback([this](const msgs::PoseEstimate& pose) { poses_.push_back({pose.timestamp, pose.T_world_body.to_se3()}); });
  }

  std::optional<std::string> push(const std::string& sensor, msgs::SensorMessage message) {
    const Status pushed = session_->push(sensor, std::move(message));
    if (pushed) return std::nullopt;
    return pushed.error().message;
  }

  std::optional<std::string> push_message(const std::string& sensor, const py::object& message) {
    return push(sensor, python::sensor_message_from_python(message));
  }

  std::optional<std::string> push_imu(const std::string& sensor, double time_s, const Eigen::Vector3d& acceleration,
                                      const Eigen::Vector3d& angular_velocity) {
    msgs::ImuMessage imu;
    imu.timestamp = time_from(time_s);
    imu.linear_acceleration = acceleration;
    imu.angular_velocity = angular_velocity;
    return push(sensor, imu);
  }

  std::optional<std::string> push_gnss(const std::string& sensor, double time_s, double latitude, double longitude, double altitude,
                                       const std::string& fix, const std::optional<Eigen::Matrix3d>& covariance) {
    msgs::GnssMessage gnss;
    gnss.timestamp = time_from(time_s);
    gnss.latitude = latitude;
    gnss.longitude = longitude;
    gnss.altitude = altitude;
    const std::optional<msgs::GnssFixType> type = msgs::gnss_fix_type_from_string(fix);
    if (!type) throw py::value_error(fmt::format("fix: expected NO_FIX, FIX_2D, FIX_3D, RTK_FLOAT or RTK_FIXED, got '{}'", fix));
    gnss.fix_type = *type;
    gnss.position_covariance = covariance;
    return push(sensor, gnss);
  }

  std::optional<std::string> push_wheels(const std::string& sensor, double time_s, double left_distance, double right_distance,
                                         double wheel_separation, double wheel_radius) {
    msgs::WheelOdometryMessage wheels;
    wheels.timestamp = time_from(time_s);
    wheels.left_distance = left_distance;
    wheels.right_distance = right_distance;
    wheels.wheel_separation = wheel_separation;
    wheels.wheel_radius = wheel_radius;
    return push(sensor, wheels);
  }

  std::optional<std::string> push_point_cloud(const std::string& sensor, double time_s, const PointRows& points,
                                              const std::optional<std::vector<double>>& times, const std::optional<std::vector<int64_t>>& rings) {
    msgs::PointCloudMessage cloud;
    cloud.timestamp = time_from(time_s);
    const std::size_t count = static_cast<std::size_t>(points.rows());
    if (times && times->size() != count) throw py::value_error(fmt::format("times: expected {} values (one per point), got {}", count, times->size()));
    if (rings && rings->size() != count) throw py::value_error(fmt::format("rings: expected {} values (one per point), got {}", count, rings->size()));
    cloud.points.reserve(count);
    for (Eigen::Index i = 0; i < points.rows(); ++i) cloud.points.push_back(points.row(i).transpose().cast<float>());
    if (times) {
      for (const double offset : *times) {
        if (!std::isfinite(offset)) throw py::value_error("times: every point time must be finite");
        cloud.point_timestamps.push_back(cloud.timestamp + Duration::from_seconds(offset));
      }
    }
    if (rings) {
      for (const int64_t ring : *rings) {
        if (ring < 0 || ring > 0xffffffffLL) throw py::value_error(fmt::format("rings: {} is not a ring index", ring));
        cloud.ring_ids.push_back(static_cast<uint32_t>(ring));
      }
    }
    return push(sensor, std::move(cloud));
  }

  // Every sensor message of the log whose topic a configured sensor reads; then flush(). A log
  // read only in part (corrupted chunks, truncated, undecodable messages) raises ValueError
  // after the replay unless allow_partial (then "partial" and "incomplete" say what was lost).
  py::dict replay(const std::string& log_path, bool allow_partial) {
    Result<std::unique_ptr<io::SensorLogReader>> reader = io::SensorLogReader::open(log_path);
    if (!reader) throw py::value_error(reader.error().message);
    const pipeline::LogReplaySummary replay = pipeline::replay_log(*session_, **reader);
    replayed_ = log_path;
    const std::string incomplete = replay.incomplete();
    if (!incomplete.empty() && !allow_partial) {
      throw py::value_error(fmt::format("partial log: {} (the session holds what was read; allow_partial=True accepts it)", incomplete));
    }
    uint64_t unmapped = 0;
    for (const auto& [topic, count] : replay.unmapped_topics) unmapped += count;
    py::dict result;
    result["messages"] = replay.messages;
    result["rejected"] = replay.rejected;
    result["unread"] = replay.unread;
    result["unmapped"] = unmapped;
    result["partial"] = !incomplete.empty();
    result["incomplete"] = incomplete;
    return result;
  }

  void flush() { session_->flush(); }
  PoseRows poses() const { return pose_rows(poses_); }
  PoseRows optimized_trajectory() const { return pose_rows(session_->optimized_trajectory()); }

  PointRows map_points() const {
    const msgs::FusionMap map = session_->map();
    if (!map.points) return PointRows(0, 3);
    PointRows rows(static_cast<Eigen::Index>(map.points->points.size()), 3);
    for (std::size_t i = 0; i < map.points->points.size(); ++i) rows.row(static_cast<Eigen::Index>(i)) = map.points->points[i].cast<double>().transpose();
    return rows;
  }

  void save_map(const std::string& path, const std::optional<std::string>& log_uri, const std::string& map_id) const {
    if (!replayed_) throw py::value_error("save_map: only a session that replayed a log (replay()) records its map's provenance");
    const Timestamp created = poses_.empty() ? Timestamp() : poses_.back().timestamp;
    Result<msgs::FusionMap> map = pipeline::replayed_map(*session_, map_id, created, config_path_, *replayed_, HANZO_FUSION_VERSION);
    if (!map) throw py::value_error(map.error().message);
    if (log_uri) map->provenance.input_logs.back().uri = *log_uri;
    if (Status written = maps::write_fusion_map(path, *map); !written) throw py::value_error(written.error().message);
  }

  py::dict summary() const {
    const pipeline::SessionSummary summary = session_->summary();
    const pipeline::MappingSummary mapping = session_->mapping_summary();
    py::list sensors;
    for (const pipeline::SensorStatistics& s : summary.sensors) {
      py::dict sensor;
      sensor["name"] = s.name;
      sensor["modality"] = std::string(config::to_string(s.modality));
      sensor["received"] = s.received;
      sensor["fused"] = s.fused;
      sensor["rejected"] = pipeline::by_name(s.rejected);
      sensor["timeouts"] = s.timeouts;
      sensors.append(sensor);
    }
    py::dict health;
    for (const pipeline::SensorHealth& entry : session_->health()) {
      py::dict item;
      item["state"] = std::string(pipeline::to_string(entry.state));
      item["reason"] = std::string(pipeline::to_string(entry.reason));
      health[py::str(entry.sensor)] = item;
    }
    py::dict result;
    result["health"] = health;
    result["mode"] = std::string(pipeline::to_string(session_->mode()));
    result["state"] = std::string(msgs::to_string(summary.state));
    result["poses"] = summary.poses;
    result["keyframes"] = summary.keyframes;
    result["sensors"] = sensors;
    result["scans_registered"] = mapping.scans_registered;
    result["map_keyframes"] = mapping.map_keyframes;
    result["map_revisits"] = mapping.map_revisits;
    result["graph_keyframes"] = mapping.graph_keyframes;
    result["graph_landmarks"] = mapping.graph_landmarks;
    result["loop_closures"] = mapping.loop_closures;
    result["gnss_factors"] = mapping.gnss_factors;
    result["graph_velocity_factors"] = mapping.graph_velocity_factors;
    return result;
  }

 private:
  std::unique_ptr<pipeline::Session> session_;
  std::vector<pipeline::StampedPose> poses_;
  std::string config_path_;
  std::optional<std::string> replayed_;  // the log replay() read
};

/// pipeline::merge_sessions of FusionMap files, the result written to `out`.
py::dict merge_maps(const std::vector<std::string>& paths, const std::string& out, const std::string& map_id, bool indoor) {
  std::vector<msgs::FusionMap> inputs;
  for (const std::string& path : paths) {
    Result<msgs::FusionMap> map = maps::read_fusion_map(path);
    if (!map) throw py::value_error(map.error().message);
    inputs.push_back(std::move(map).value());
  }
  pipeline::SessionMergeConfig config;
  if (indoor) {
    config.odometry.map.voxel_size = 0.5;
    config.odometry.source_voxel_size = 0.25;
  }
  Result<pipeline::SessionMergeResult> merged = [&] {
    py::gil_scoped_release released;
    return pipeline::merge_sessions(inputs, config);
  }();
  if (!merged) throw py::value_error(merged.error().message);
  merged->merged.map_id = map_id;
  if (Status written = maps::write_fusion_map(out, merged->merged); !written) throw py::value_error(written.error().message);
  py::list joins;
  for (const pipeline::SessionJoin& join : merged->joins) {
    py::dict entry;
    entry["map"] = paths[join.map];
    entry["joined_to"] = paths[join.joined_to];
    entry["loops"] = join.loops;
    entry["T_joined_map"] = join.T_joined_map.matrix();
    entry["scale"] = join.scale;
    joins.append(entry);
  }
  // Rows (t, x, y, z, qw, qx, qy, qz) of a keyframe layer and each keyframe's source.
  const auto keyframe_rows = [](const auto& keyframes, const auto& pose_of) {
    PoseRows poses(static_cast<Eigen::Index>(keyframes.size()), 8);
    for (std::size_t k = 0; k < keyframes.size(); ++k) {
      const msgs::Pose& pose = pose_of(keyframes[k]);
      const Eigen::Quaterniond& q = pose.orientation;
      poses.row(static_cast<Eigen::Index>(k)) << keyframes[k].time.seconds(), pose.position.transpose(), q.w(), q.x(), q.y(), q.z();
    }
    return poses;
  };
  const auto sources_of = [](const auto& layer) {
    py::list sources;
    for (const auto& keyframe : layer.keyframes) sources.append(layer.sources.at(keyframe.source));
    return sources;
  };
  const msgs::LidarKeyframeLayer lidar = merged->merged.lidar_keyframes.value_or(msgs::LidarKeyframeLayer{});
  const msgs::VisualLandmarkLayer visual = merged->merged.visual_landmarks.value_or(msgs::VisualLandmarkLayer{});
  py::dict result;
  result["map"] = out;
  result["joins"] = joins;
  result["keyframe_poses"] = keyframe_rows(lidar.keyframes, [](const msgs::LidarKeyframe& keyframe) -> const msgs::Pose& { return keyframe.T_world_lidar; });
  result["keyframe_sources"] = sources_of(lidar);
  result["visual_keyframe_poses"] =
      keyframe_rows(visual.keyframes, [](const msgs::VisualKeyframe& keyframe) -> const msgs::Pose& { return keyframe.T_world_camera; });
  result["visual_keyframe_sources"] = sources_of(visual);
  result["keyframes"] = merged->keyframes;
  result["queries"] = merged->queries;
  result["candidates"] = merged->candidates;
  result["verified"] = merged->verified;
  result["visual_queries"] = merged->visual_queries;
  result["visual_verified"] = merged->visual_verified;
  result["inter_session_loops"] = merged->inter_session_loops;
  result["points"] = merged->merged.points ? merged->merged.points->points.size() : 0;
  return result;
}

}  // namespace

void bind_session(py::module_& module) {
  py::class_<PySession>(module, "Session",
                        "The whole pipeline (filter, LiDAR odometry, keyframe graph, loop closure, map) in replay mode; "
                        "docs/python.md")
      .def(py::init<const std::string&, const std::optional<std::string>&, int>(), py::arg("config"), py::arg("calibration") = std::nullopt,
           py::arg("threads") = 1, "config: fusion configuration YAML path; calibration: calibration YAML path")
      .def("push", &PySession::push_message, py::arg("sensor"), py::arg("message"),
           "A hanzo.fusion.messages message (Imu, PointCloud, Image, Gnss, WheelOdometry, Radar) from the named sensor. "
           "Returns None, or the rejection 'reason: detail'")
      .def("push_imu", &PySession::push_imu, py::arg("sensor"), py::arg("time_s"), py::arg("acceleration"), py::arg("angular_velocity"),
           "Specific force (m/s^2) and turn rate (rad/s) in the IMU frame. Returns None, or the rejection 'reason: detail'")
      .def("push_gnss", &PySession::push_gnss, py::arg("sensor"), py::arg("time_s"), py::arg("latitude"), py::arg("longitude"),
           py::arg("altitude"), py::arg("fix") = "FIX_3D", py::arg("covariance") = std::nullopt,
           "WGS84 degrees and metres above the ellipsoid; covariance 3 x 3 ENU m^2")
      .def("push_wheels", &PySession::push_wheels, py::arg("sensor"), py::arg("time_s"), py::arg("left_distance"), py::arg("right_distance"),
           py::arg("wheel_separation"), py::arg("wheel_radius") = 0.0, "Cumulative wheel distances (m)")
      .def("push_point_cloud", &PySession::push_point_cloud, py::arg("sensor"), py::arg("time_s"), py::arg("points"),
           py::arg("times") = std::nullopt, py::arg("rings") = std::nullopt,
           "A LiDAR sweep: N x 3 points (sensor frame, m), optional per-point times (s after time_s) and ring indices")
      .def("replay", &PySession::replay, py::arg("log"), py::arg("allow_partial") = false,
           "Pushes every message of a sensor log (MCAP) a sensor reads, then flushes; raises ValueError for a log read only in part "
           "(corrupted chunks, truncated) unless allow_partial")
      .def("flush", &PySession::flush, "Fuses what still waits (call at the end of the data)")
      .def("poses", &PySession::poses, "Real-time poses as emitted: N x 8 (t, x, y, z, qw, qx, qy, qz), body in the world")
      .def("optimized_trajectory", &PySession::optimized_trajectory, "The same poses moved onto the optimized graph: N x 8")
      .def("map_points", &PySession::map_points, "The map's points: N x 3 (world, m)")
      .def("save_map", &PySession::save_map, py::arg("path"), py::arg("log_uri") = std::nullopt, py::arg("map_id") = "replay",
           "After replay(): writes the session's FusionMap (every layer, the configuration and the log's SHA-256 as provenance, "
           "the log named by log_uri when given, e.g. where a local copy came from; hanzo-fusion map info reads it) to a .fmap file; "
           "raises ValueError when it cannot be written")
      .def("summary", &PySession::summary, "Counts per sensor and of the mapping");
  module.def("merge_maps", &merge_maps, py::arg("maps"), py::arg("out"), py::arg("map_id") = "merged", py::arg("indoor") = false,
             "Joins FusionMap files with LiDAR or visual keyframes (written by sessions) into one optimized keyframe graph without an "
             "initial guess (Scan Context or bag-of-words candidates, registration or landmark alignment, inter-session loops; the first "
             "map's frame) and writes the merged map to out. Returns the joins, counts and the merged keyframes (keyframe_poses: rows t, x, "
             "y, z, qw, qx, qy, qz of T_world_lidar; keyframe_sources: the map id of each; visual_keyframe_poses / visual_keyframe_sources: "
             "the same of T_world_camera); raises ValueError when a map cannot be read or shares no place with the others");
}
