#include "json_codec.hpp"

#include <cmath>
#include <initializer_list>
#include <iterator>

#include <Eigen/Cholesky>
#include <fmt/format.h>

namespace hanzo::fusion::service::detail {
namespace {

using nlohmann::json;

json vector_json(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

// An array of `count` finite numbers.
ApiResult<std::vector<double>> numbers(const json& value, std::size_t count, const std::string& field) {
  if (!value.is_array() || value.size() != count) {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("{}: expected an array of {} numbers", field, count), field};
  }
  std::vector<double> out;
  for (const json& element : value) {
    if (!element.is_number() || !std::isfinite(element.get<double>())) {
      return ApiError{ErrorCode::kInvalidArgument, fmt::format("{}: expected finite numbers", field), field};
    }
    out.push_back(element.get<double>());
  }
  return out;
}

// {"position": [x, y, z], "orientation_wxyz": [w, x, y, z]} (orientation optional: identity).
ApiResult<SE3> parse_pose(const json& pose, const std::string& field) {
  if (!pose.is_object()) return ApiError{ErrorCode::kInvalidArgument, field + ": expected {position, orientation_wxyz}", field};
  if (auto keys = check_keys(pose, {"position", "orientation_wxyz"}); !keys) return keys.error();
  auto position = numbers(pose.value("position", json()), 3, field + ".position");
  if (!position) return position.error();
  auto orientation = numbers(pose.value("orientation_wxyz", json::array({1, 0, 0, 0})), 4, field + ".orientation_wxyz");
  if (!orientation) return orientation.error();
  const std::vector<double>& w_x_y_z = orientation.value();
  const std::vector<double>& xyz = position.value();
  Eigen::Quaterniond q(w_x_y_z[0], w_x_y_z[1], w_x_y_z[2], w_x_y_z[3]);
  if (std::abs(q.norm() - 1.0) > 1e-3) {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("{}.orientation_wxyz: norm {} is not 1", field, q.norm()), field + ".orientation_wxyz"};
  }
  return SE3(SO3(q.normalized()), Eigen::Vector3d(xyz[0], xyz[1], xyz[2]));
}

json pose_json(const SE3& pose) {
  const Eigen::Quaterniond q = pose.rotation().quaternion();
  return {{"position", vector_json(pose.translation())}, {"orientation_wxyz", json::array({q.w(), q.x(), q.y(), q.z()})}};
}

// A non-negative finite number (or the default when absent).
ApiResult<double> optional_non_negative(const json& object, const std::string& key, double fallback) {
  if (!object.contains(key) || object[key].is_null()) return fallback;
  if (!object[key].is_number() || !std::isfinite(object[key].get<double>()) || object[key].get<double>() < 0) {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("{}: expected a finite number >= 0", key), key};
  }
  return object[key].get<double>();
}

ApiResult<std::string> optional_string(const json& object, const std::string& key) {
  if (!object.contains(key) || object[key].is_null()) return std::string();
  if (!object[key].is_string()) {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("{}: expected a string, got {}", key, object[key].type_name()), key};
  }
  return object[key].get<std::string>();
}

// A YAML document given as text, or as a JSON object (JSON is YAML), under `root_key` (added
// when the object omits it).
ApiResult<std::string> yaml_document(const json& object, const std::string& key, const std::string& root_key) {
  if (!object.contains(key) || object[key].is_null()) return std::string();
  const json& value = object[key];
  if (value.is_string()) return value.get<std::string>();
  if (!value.is_object()) {
    return ApiError{ErrorCode::kInvalidArgument,
                    fmt::format("{}: expected YAML text or a JSON object, got {}", key, value.type_name()), key};
  }
  if (root_key.empty() || value.contains(root_key)) return value.dump();
  return json{{root_key, value}}.dump();
}

}  // namespace

ApiResult<json> parse_object(const std::string& body) {
  if (body.empty()) return ApiError{ErrorCode::kInvalidArgument, "the request body is empty (expected a JSON object)", "body"};
  json document;
  try {
    document = json::parse(body);
  } catch (const json::parse_error& error) {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("malformed JSON at byte {}: {}", error.byte, error.what()), "body"};
  } catch (const json::exception& error) {  // out_of_range: a number too large for any type
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("malformed JSON: {}", error.what()), "body"};
  }
  if (!document.is_object()) return ApiError{ErrorCode::kInvalidArgument, "expected a JSON object", "body"};
  return document;
}

ApiStatus check_keys(const json& object, std::initializer_list<std::string_view> allowed) {
  for (const auto& [key, value] : object.items()) {
    if (std::find(allowed.begin(), allowed.end(), key) == allowed.end()) {
      std::string names;
      for (std::string_view name : allowed) names += (names.empty() ? "" : ", ") + std::string(name);
      return ApiError{ErrorCode::kInvalidArgument, fmt::format("unknown field '{}' (known: {})", key, names), key};
    }
  }
  return api_ok();
}

json pose_to_json(const msgs::PoseEstimate& pose) {
  const Eigen::Quaterniond& q = pose.T_world_body.orientation;
  json result = {
      {"timestamp_ns", pose.timestamp.nanoseconds()},
      {"frame_id", pose.frame_id},
      {"child_frame_id", pose.child_frame_id},
      {"position", vector_json(pose.T_world_body.position)},
      {"orientation_wxyz", json::array({q.w(), q.x(), q.y(), q.z()})},
      {"velocity", vector_json(pose.velocity)},
      {"state", msgs::to_string(pose.status.state)},
      {"active_modalities", pose.status.active_modalities},
      {"active_sensors", pose.status.active_sensors},
      {"sensor_health", json::array()},
      {"covariance", nullptr},
  };
  for (const msgs::SensorHealthStatus& health : pose.status.sensor_health) {
    result["sensor_health"].push_back({{"sensor", health.sensor}, {"state", msgs::to_string(health.state)}, {"reason", msgs::to_string(health.reason)}});
  }
  if (pose.pose_covariance) {
    json covariance = json::array();
    for (int row = 0; row < 6; ++row) {
      for (int column = 0; column < 6; ++column) covariance.push_back((*pose.pose_covariance)(row, column));
    }
    result["covariance"] = std::move(covariance);
  }
  return result;
}

json session_to_json(const SessionInfo& info) {
  json sensors = json::array();
  for (const pipeline::SensorStatistics& sensor : info.summary.sensors) {
    json entry = {{"name", sensor.name},
                  {"modality", config::to_string(sensor.modality)},
                  {"received", sensor.received},
                  {"fused", sensor.fused},
                  {"rejected", pipeline::by_name(sensor.rejected)},
                  {"timeouts", sensor.timeouts},
                  {"timed_out", sensor.timed_out}};
    for (const pipeline::SensorHealth& health : info.health) {
      if (health.sensor == sensor.name) entry["health"] = {{"state", pipeline::to_string(health.state)}, {"reason", pipeline::to_string(health.reason)}};
    }
    sensors.push_back(std::move(entry));
  }
  return {
      {"id", info.id},
      {"name", info.name},
      {"organization", info.organization},
      {"status", info.ended ? "ended" : "active"},
      {"created_ns", info.created.nanoseconds()},
      {"ended_ns", info.ended ? json(info.ended->nanoseconds()) : json(nullptr)},
      // The live state; for a session restored after a restart that has not emitted a pose
      // yet, its last stored pose's.
      {"tracking_state", msgs::to_string(info.summary.poses == 0 && info.latest_pose ? info.latest_pose->status.state : info.summary.state)},
      {"filter", info.summary.filter},
      {"sensors", std::move(sensors)},
      {"poses", info.summary.poses},
      {"keyframes", info.summary.keyframes},
      {"stored_poses", info.stored_poses},
      {"stored_through_ns", info.stored_through ? json(info.stored_through->nanoseconds()) : json(nullptr)},
      {"pose_subscribers", info.pose_subscribers},
      {"keyframe_subscribers", info.keyframe_subscribers},
      {"map_subscribers", info.map_subscribers},
      {"latest_pose", info.latest_pose ? pose_to_json(*info.latest_pose) : json(nullptr)},
      {"mapping", mapping_to_json(info.mapping)},
      {"config", info.config_yaml},
      {"calibration", info.calibration_yaml},
      {"recording", info.recording ? recording_to_json(*info.recording) : json(nullptr)},
      {"replica", info.replica.empty() ? json(nullptr) : json(info.replica)},
  };
}

json recording_to_json(const RecordingInfo& recording) {
  return {{"file", recording.file},
          {"status", recording.active ? "recording" : "finished"},
          {"encrypted", recording.encrypted},
          {"location", recording.archived ? json(recording.location) : json(nullptr)},  // server paths stay private
          {"privacy", recording.privacy},
          {"messages", recording.messages},
          {"invalid_messages", recording.invalid_messages},
          {"dropped_messages", recording.dropped_messages},
          {"bytes", recording.bytes},
          {"privacy_audit", {{"images", recording.images}, {"redacted_images", recording.redacted_images}, {"faces", recording.faces},
                             {"licence_plates", recording.licence_plates}}},
          {"error", recording.error ? json(*recording.error) : json(nullptr)}};
}

json mapping_to_json(const pipeline::MappingSummary& mapping) {
  return {
      {"scans_received", mapping.scans_received},
      {"scans_registered", mapping.scans_registered},
      {"scans_refused", mapping.scans_refused},
      {"degenerate_scans", mapping.degenerate_scans},
      {"weather_degraded_scans", mapping.weather_degraded_scans},
      {"graph_keyframes", mapping.graph_keyframes},
      {"graph_landmarks", mapping.graph_landmarks},
      {"graph_projections", mapping.graph_projections},
      {"graph_imu_factors", mapping.graph_imu_factors},
      {"graph_lidar_factors", mapping.graph_lidar_factors},
      {"splat_views", mapping.splat_views},
      {"splat_iterations", mapping.splat_iterations},
      {"splat_gaussians", mapping.splat_gaussians},
      {"map_keyframes", mapping.map_keyframes},
      {"map_revisits", mapping.map_revisits},
      {"loop_candidates", mapping.loop_candidates},
      {"loop_closures", mapping.loop_closures},
      {"manual_loop_closures", mapping.manual_loop_closures},
      {"relocalizations", mapping.relocalizations},
      {"gnss_factors", mapping.gnss_factors},
      {"graph_velocity_factors", mapping.graph_velocity_factors},
      {"map_version", mapping.map_version},
      {"map_memory_bytes", mapping.map_memory_bytes},
      {"last_registration_ms", mapping.last_registration_ms},
      {"last_correction_m", mapping.last_correction_m},
      {"camera_frames_tracked", mapping.camera_frames_tracked},
      {"camera_frames_lost", mapping.camera_frames_lost},
      {"camera_standstill_frames", mapping.camera_standstill_frames},
      {"camera_dark_frames", mapping.camera_dark_frames},
      {"camera_glare_frames", mapping.camera_glare_frames},
      {"camera_motion_blur_frames", mapping.camera_motion_blur_frames},
      {"camera_features", mapping.camera_features},
      {"camera_feature_ms", mapping.camera_feature_ms},
      {"camera_mapping_ms", mapping.camera_mapping_ms},
      {"camera_learned_matcher", mapping.camera_learned_matcher},
      {"visual_place_recognition", mapping.visual_place_recognition},
      {"detections_received", mapping.detections_received},
      {"detections_computed", mapping.detections_computed},
      {"detector_failures", mapping.detector_failures},
      {"detector_ms", mapping.detector_ms},
      {"detections_refused", mapping.detections_refused},
      {"detections_matched", mapping.detections_matched},
      {"detections_late", mapping.detections_late},
      {"images_without_detections", mapping.images_without_detections},
      {"images_masked", mapping.images_masked},
      {"dynamic_objects_masked", mapping.dynamic_objects_masked},
      {"masked_image_share", mapping.masked_image_share},
      {"lidar_points_labelled", mapping.lidar_points_labelled},
      {"lidar_points_masked", mapping.lidar_points_masked},
      {"map_points_moving_removed", mapping.map_points_moving_removed},
  };
}

json map_to_json(const msgs::FusionMap& map) {
  json layers = json::object();
  if (map.points) layers["points"] = {{"count", map.points->points.size()}, {"voxel_size", map.points->voxel_size}};
  if (map.occupancy) {
    layers["occupancy"] = {{"size", {map.occupancy->size_x, map.occupancy->size_y, map.occupancy->size_z}},
                           {"resolution", map.occupancy->resolution}};
  }
  if (map.tsdf) layers["tsdf"] = {{"blocks", map.tsdf->blocks.size()}};
  if (map.mesh) layers["mesh"] = {{"vertices", map.mesh->vertices.size()}};
  if (map.visual_landmarks) layers["visual_landmarks"] = {{"landmarks", map.visual_landmarks->positions.size()}, {"keyframes", map.visual_landmarks->keyframes.size()}};
  return {{"map_id", map.map_id}, {"version", map.version}, {"created_ns", map.created.nanoseconds()},
          {"frame_id", map.frame_id}, {"format_version", map.format_version}, {"layers", std::move(layers)}};
}

json loop_closure_to_json(const pipeline::LoopClosureOutcome& outcome) {
  return {{"from_keyframe", outcome.from_keyframe},
          {"to_keyframe", outcome.to_keyframe},
          {"relative_pose", pose_json(outcome.T_from_to)},
          {"registered", outcome.registered},
          {"inlier_rmse_m", outcome.inlier_rmse},
          {"inlier_fraction", outcome.inlier_fraction},
          {"correction_m", outcome.correction_m}};
}

ApiResult<pipeline::LoopClosureRequest> parse_loop_closure(const std::string& body) {
  pipeline::LoopClosureRequest request;
  if (body.empty()) return request;  // search for the newest keyframe
  auto document = parse_object(body);
  if (!document) return document.error();
  const json& object = document.value();
  if (auto keys = check_keys(object, {"from_keyframe", "to_keyframe", "relative_pose", "covariance"}); !keys) return keys.error();
  for (const char* key : {"from_keyframe", "to_keyframe"}) {
    if (!object.contains(key) || object[key].is_null()) continue;
    if (!object[key].is_number_unsigned()) {
      return ApiError{ErrorCode::kInvalidArgument, fmt::format("{}: expected a keyframe id (a non-negative integer)", key), key};
    }
    (std::string_view(key) == "from_keyframe" ? request.from_keyframe : request.to_keyframe) = object[key].get<uint64_t>();
  }
  if (object.contains("relative_pose") && !object["relative_pose"].is_null()) {
    auto pose = parse_pose(object["relative_pose"], "relative_pose");
    if (!pose) return pose.error();
    request.T_from_to = pose.value();
  }
  if (object.contains("covariance") && !object["covariance"].is_null()) {
    auto values = numbers(object["covariance"], 36, "covariance");
    if (!values) return values.error();
    const Eigen::Matrix<double, 6, 6> covariance = Eigen::Map<const Eigen::Matrix<double, 6, 6, Eigen::RowMajor>>(values.value().data());
    if (!covariance.isApprox(covariance.transpose(), 1e-9) || covariance.llt().info() != Eigen::Success) {
      return ApiError{ErrorCode::kInvalidArgument, "covariance: not symmetric positive definite", "covariance"};
    }
    request.covariance = covariance;
  }
  return request;
}

json relocalization_to_json(const RelocalizeResult& result) {
  json answer = {{"map_id", result.map_id}, {"version", result.version}};
  if (result.outcome) {
    const pipeline::RelocalizationOutcome& outcome = *result.outcome;
    const lidar::MapLocalization& found = outcome.localization;
    answer.update({{"sensor", "lidar"},
                   {"T_map_world", pose_json(outcome.T_map_world)},
                   {"T_map_lidar", pose_json(outcome.T_map_lidar)},
                   {"keyframe_id", outcome.keyframe_id},
                   {"global_search", found.global},
                   {"score", found.score},
                   {"inlier_rmse_m", found.inlier_rmse},
                   {"inlier_fraction", found.inlier_fraction},
                   {"seen_through_fraction", found.seen_through_fraction},
                   {"seconds", found.seconds}});
  }
  if (result.camera_outcome) {
    const pipeline::CameraRelocalizationOutcome& outcome = *result.camera_outcome;
    json placements = json::array();
    for (const pipeline::CameraPlacement& placement : outcome.placements) {
      json entry = {{"timestamp_ns", placement.time.nanoseconds()}, {"placed", placement.placed}};
      if (placement.placed) {
        entry.update({{"T_map_camera", pose_json(placement.T_map_camera)},
                      {"inliers", placement.inliers},
                      {"map_keyframe", placement.map_keyframe},
                      {"place_score", placement.place_score},
                      {"agrees", placement.agrees}});
      } else {
        entry["reason"] = placement.reason;
      }
      placements.push_back(std::move(entry));
    }
    answer.update({{"sensor", "camera"},
                   {"T_map_world", pose_json(outcome.T_map_world)},
                   {"keyframe_id", outcome.keyframe_id},
                   {"agreeing_frames", outcome.agreeing_frames},
                   {"place_recognition", outcome.place_recognition},
                   {"correction_m", outcome.correction_m},
                   {"placements", std::move(placements)}});
  }
  return answer;
}

ApiResult<RelocalizeRequest> parse_relocalize(const std::string& body) {
  auto document = parse_object(body);
  if (!document) return document.error();
  const json& object = document.value();
  if (auto keys = check_keys(object, {"map_id", "version", "initial_pose", "linear_window_m", "angular_window_rad", "sensor", "frames",
                                      "min_agreeing_frames", "agreement_m", "agreement_rad"});
      !keys) {
    return keys.error();
  }
  RelocalizeRequest request;
  auto map_id = optional_string(object, "map_id");
  if (!map_id) return map_id.error();
  if (map_id->empty()) return ApiError{ErrorCode::kInvalidArgument, "map_id: missing (the stored map to relocalize against)", "map_id"};
  request.map_id = std::move(map_id).value();
  if (object.contains("version") && !object["version"].is_null()) {
    if (!object["version"].is_number_unsigned() || object["version"].get<uint64_t>() == 0) {
      return ApiError{ErrorCode::kInvalidArgument, "version: expected a stored version (an integer >= 1)", "version"};
    }
    request.version = object["version"].get<uint64_t>();
  }
  if (object.contains("initial_pose") && !object["initial_pose"].is_null()) {
    auto pose = parse_pose(object["initial_pose"], "initial_pose");
    if (!pose) return pose.error();
    request.relocalization.T_map_body_guess = pose.value();
  }
  auto linear = optional_non_negative(object, "linear_window_m", request.relocalization.linear_window);
  if (!linear) return linear.error();
  auto angular = optional_non_negative(object, "angular_window_rad", request.relocalization.angular_window);
  if (!angular) return angular.error();
  request.relocalization.linear_window = linear.value();
  request.relocalization.angular_window = angular.value();
  auto sensor_field = optional_string(object, "sensor");
  if (!sensor_field) return sensor_field.error();
  const std::string& sensor = sensor_field.value();
  if (sensor == "lidar") {
    request.sensor = RelocalizeSensor::kLidar;
  } else if (sensor == "camera") {
    request.sensor = RelocalizeSensor::kCamera;
  } else if (!sensor.empty()) {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("sensor: expected lidar or camera, got '{}'", sensor), "sensor"};
  }
  pipeline::CameraRelocalizationRequest& camera = request.camera;
  for (const auto& [key, target] : {std::pair<const char*, int*>{"frames", &camera.frames}, {"min_agreeing_frames", &camera.min_agreeing_frames}}) {
    if (!object.contains(key) || object[key].is_null()) continue;
    if (!object[key].is_number_integer() || object[key].get<int64_t>() < 1 || object[key].get<int64_t>() > pipeline::Session::kRecentCameraImages) {
      return ApiError{ErrorCode::kInvalidArgument, fmt::format("{}: expected an integer in 1..{}", key, pipeline::Session::kRecentCameraImages), key};
    }
    *target = object[key].get<int>();
  }
  if (camera.min_agreeing_frames > camera.frames) {
    return ApiError{ErrorCode::kInvalidArgument, fmt::format("min_agreeing_frames: {} is more than frames ({})", camera.min_agreeing_frames, camera.frames),
                    "min_agreeing_frames"};
  }
  auto agreement_m = optional_non_negative(object, "agreement_m", camera.agreement_m);
  if (!agreement_m) return agreement_m.error();
  auto agreement_rad = optional_non_negative(object, "agreement_rad", camera.agreement_rad);
  if (!agreement_rad) return agreement_rad.error();
  camera.agreement_m = agreement_m.value();
  camera.agreement_rad = agreement_rad.value();
  return request;
}

json stored_map_to_json(const StoredMap& map) {
  json versions = json::array();
  for (const maps::MapVersionInfo& version : map.versions) {
    versions.push_back({{"version", version.version}, {"parent_version", version.parent_version},
                        {"created_ns", version.created.nanoseconds()}, {"bytes", version.file_bytes}});
  }
  return {{"map_id", map.record.map_id},
          {"name", map.record.name},
          {"session_id", map.record.session_id.empty() ? json(nullptr) : json(map.record.session_id)},
          {"created_ns", map.record.created.nanoseconds()},
          {"latest_version", map.versions.empty() ? json(nullptr) : json(map.versions.back().version)},
          {"versions", std::move(versions)}};
}

json error_to_json(const ApiError& error) {
  return {{"error", {{"code", to_string(error.code)}, {"message", error.message}, {"field", error.field}}}};
}

ApiResult<CreateSessionRequest> parse_create_session(const std::string& body) {
  auto document = parse_object(body);
  if (!document) return document.error();
  const json& object = document.value();
  if (auto keys = check_keys(object, {"name", "config", "calibration", "record", "privacy"}); !keys) return keys.error();
  CreateSessionRequest request;
  auto name = optional_string(object, "name");
  if (!name) return name.error();
  request.name = name.value();
  if (object.contains("record") && !object["record"].is_null()) {
    if (!object["record"].is_boolean()) return ApiError{ErrorCode::kInvalidArgument, "record: expected true or false", "record"};
    request.record = object["record"].get<bool>();
  }
  auto privacy = optional_string(object, "privacy");
  if (!privacy) return privacy.error();
  request.privacy = privacy.value();
  if (!object.contains("config")) return ApiError{ErrorCode::kInvalidArgument, "config is missing (the fusion configuration)", "config"};
  auto configuration = yaml_document(object, "config", "fusion");
  if (!configuration) return configuration.error();
  request.config_yaml = configuration.value();
  auto calibration = yaml_document(object, "calibration", "calibration");
  if (!calibration) return calibration.error();
  request.calibration_yaml = calibration.value();
  return request;
}

ApiResult<SensorRegistration> parse_sensor_registration(const std::string& body) {
  auto document = parse_object(body);
  if (!document) return document.error();
  const json& object = document.value();
  if (auto keys = check_keys(object, {"name", "config", "calibration"}); !keys) return keys.error();
  SensorRegistration registration;
  auto name = optional_string(object, "name");
  if (!name) return name.error();
  if (name.value().empty()) return ApiError{ErrorCode::kInvalidArgument, "name is missing (the sensor's name)", "name"};
  registration.name = name.value();
  if (!object.contains("config")) {
    return ApiError{ErrorCode::kInvalidArgument, "config is missing (the sensor's configuration entry)", "config"};
  }
  auto configuration = yaml_document(object, "config", "");
  if (!configuration) return configuration.error();
  registration.config_yaml = configuration.value();
  auto calibration = yaml_document(object, "calibration", "");
  if (!calibration) return calibration.error();
  registration.calibration_yaml = calibration.value();
  return registration;
}

std::string poses_to_tum(const std::vector<msgs::PoseEstimate>& poses) {
  std::string text;
  for (const msgs::PoseEstimate& pose : poses) {
    const Eigen::Vector3d& p = pose.T_world_body.position;
    const Eigen::Quaterniond& q = pose.T_world_body.orientation;
    text += fmt::format("{}.{:09d} {} {} {} {} {} {} {}\n", pose.timestamp.nanoseconds() / 1'000'000'000,
                        pose.timestamp.nanoseconds() % 1'000'000'000, p.x(), p.y(), p.z(), q.x(), q.y(), q.z(), q.w());
  }
  return text;
}

std::string trajectory_page_to_json(const std::vector<msgs::PoseEstimate>& poses, std::optional<Timestamp> next_after) {
  fmt::memory_buffer out;
  const auto number = [&out](double value) {
    if (std::isfinite(value)) {
      fmt::format_to(std::back_inserter(out), "{}", value);
    } else {
      fmt::format_to(std::back_inserter(out), "null");  // as nlohmann::json writes them
    }
  };
  const auto numbers = [&](std::initializer_list<double> values) {
    out.push_back('[');
    bool first = true;
    for (double value : values) {
      if (!first) out.push_back(',');
      first = false;
      number(value);
    }
    out.push_back(']');
  };
  const auto text = [&out](const std::string& value) { fmt::format_to(std::back_inserter(out), "{}", json(value).dump()); };
  fmt::format_to(std::back_inserter(out), "{{\"next_after\":");
  if (next_after) {
    fmt::format_to(std::back_inserter(out), "{}", next_after->nanoseconds());
  } else {
    fmt::format_to(std::back_inserter(out), "null");
  }
  fmt::format_to(std::back_inserter(out), ",\"poses\":[");
  for (std::size_t i = 0; i < poses.size(); ++i) {
    const msgs::PoseEstimate& pose = poses[i];
    const Eigen::Vector3d& p = pose.T_world_body.position;
    const Eigen::Quaterniond& q = pose.T_world_body.orientation;
    if (i > 0) out.push_back(',');
    fmt::format_to(std::back_inserter(out), "{{\"active_modalities\":{},\"active_sensors\":[", pose.status.active_modalities);
    for (std::size_t s = 0; s < pose.status.active_sensors.size(); ++s) {
      if (s > 0) out.push_back(',');
      text(pose.status.active_sensors[s]);
    }
    fmt::format_to(std::back_inserter(out), "],\"child_frame_id\":");
    text(pose.child_frame_id);
    fmt::format_to(std::back_inserter(out), ",\"covariance\":");
    if (pose.pose_covariance) {
      out.push_back('[');
      for (int k = 0; k < 36; ++k) {
        if (k > 0) out.push_back(',');
        number((*pose.pose_covariance)(k / 6, k % 6));
      }
      out.push_back(']');
    } else {
      fmt::format_to(std::back_inserter(out), "null");
    }
    fmt::format_to(std::back_inserter(out), ",\"frame_id\":");
    text(pose.frame_id);
    fmt::format_to(std::back_inserter(out), ",\"orientation_wxyz\":");
    numbers({q.w(), q.x(), q.y(), q.z()});
    fmt::format_to(std::back_inserter(out), ",\"position\":");
    numbers({p.x(), p.y(), p.z()});
    fmt::format_to(std::back_inserter(out), ",\"sensor_health\":[");
    for (std::size_t h = 0; h < pose.status.sensor_health.size(); ++h) {
      const msgs::SensorHealthStatus& health = pose.status.sensor_health[h];
      fmt::format_to(std::back_inserter(out), "{}{{\"reason\":", h > 0 ? "," : "");
      text(std::string(msgs::to_string(health.reason)));
      fmt::format_to(std::back_inserter(out), ",\"sensor\":");
      text(health.sensor);
      fmt::format_to(std::back_inserter(out), ",\"state\":");
      text(std::string(msgs::to_string(health.state)));
      out.push_back('}');
    }
    fmt::format_to(std::back_inserter(out), "],\"state\":");
    text(std::string(msgs::to_string(pose.status.state)));
    fmt::format_to(std::back_inserter(out), ",\"timestamp_ns\":{},\"velocity\":", pose.timestamp.nanoseconds());
    numbers({pose.velocity.x(), pose.velocity.y(), pose.velocity.z()});
    out.push_back('}');
  }
  fmt::format_to(std::back_inserter(out), "]}}");
  return fmt::to_string(out);
}

}  // namespace hanzo::fusion::service::detail
