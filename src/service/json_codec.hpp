#pragma once
// JSON shapes of the REST API (docs/server.md shows examples; docs/openapi.json is normative).
#include <initializer_list>
#include <optional>
#include <string>
#include <string_view>
#include <variant>

#include <nlohmann/json.hpp>

#include "hanzo/fusion/calib/camera_calibration.hpp"
#include "hanzo/fusion/calib/motion_calibration.hpp"
#include "hanzo/fusion/service/api_error.hpp"
#include "hanzo/fusion/service/session_manager.hpp"

namespace hanzo::fusion::service::detail {

/// A request body as a JSON object, or the 400 that names what is wrong with it (field "body").
ApiResult<nlohmann::json> parse_object(const std::string& body);
/// 400 naming the first key of `object` that is not in `allowed`.
ApiStatus check_keys(const nlohmann::json& object, std::initializer_list<std::string_view> allowed);

nlohmann::json pose_to_json(const msgs::PoseEstimate& pose);
nlohmann::json session_to_json(const SessionInfo& info);
nlohmann::json recording_to_json(const RecordingInfo& recording);
nlohmann::json error_to_json(const ApiError& error);
nlohmann::json mapping_to_json(const pipeline::MappingSummary& mapping);
/// A map's metadata and layer sizes (GET /v1/sessions/{id}/map?format=json).
nlohmann::json map_to_json(const msgs::FusionMap& map);
nlohmann::json loop_closure_to_json(const pipeline::LoopClosureOutcome& outcome);
/// The outcome of either sensor's relocalization, with "sensor": "lidar" or "camera".
nlohmann::json relocalization_to_json(const RelocalizeResult& result);
/// A stored map with its versions (GET /v1/maps, /v1/maps/{id}?format=json).
nlohmann::json stored_map_to_json(const StoredMap& map);

/// The body of POST /v1/sessions: {"name": "...", "config": TEXT|OBJECT, "calibration": TEXT|OBJECT}.
ApiResult<CreateSessionRequest> parse_create_session(const std::string& body);
/// The body of POST /v1/sessions/{id}/sensors: {"name": "...", "config": TEXT|OBJECT, "calibration": TEXT|OBJECT}.
ApiResult<SensorRegistration> parse_sensor_registration(const std::string& body);

/// The body of POST /v1/sessions/{id}/loop-closure: empty or {} (search for the newest map
/// keyframe), {"from_keyframe": N, "to_keyframe": M} (register them), plus
/// "relative_pose": {"position": [x, y, z], "orientation_wxyz": [w, x, y, z]} (add as given) and
/// optionally "covariance": 36 numbers, row-major, over (rho, phi).
ApiResult<pipeline::LoopClosureRequest> parse_loop_closure(const std::string& body);

/// The body of POST /v1/sessions/{id}/relocalize: {"map_id": "...", "version": N (latest when
/// absent), "initial_pose": {"position": [...], "orientation_wxyz": [...]} (the body's pose in
/// the map; absent: search the whole map), "linear_window_m": 5, "angular_window_rad": 0.5,
/// "sensor": "lidar" | "camera" (absent: the LiDAR when the session maps one), and for cameras
/// "frames": 3, "min_agreeing_frames": 2, "agreement_m": 0.3, "agreement_rad": 0.05}.
ApiResult<RelocalizeRequest> parse_relocalize(const std::string& body);

struct MotionCalibrateRequest {
  calib::MotionCalibrationInput input;
  calib::MotionCalibrationConfig config;
};

struct CameraCalibrateRequest {
  std::string sensor;
  std::vector<msgs::ImageMessage> images;  ///< decoded: mono8 or bgr8
  calib::CameraCalibrationConfig config;
};

using CalibrateRequest = std::variant<MotionCalibrateRequest, CameraCalibrateRequest>;

/// The body of POST /v1/calibrate (calibration_codec.cpp); "procedure" picks the kind:
/// - "motion" (the default): {"sensor": "lidar", "sensor_poses": [[t, x, y, z, qx, qy, qz, qw],
///   ...] (TUM rows, seconds), and "body_poses" (TUM rows) or "gyro" ([t, wx, wy, wz] rows,
///   rad/s), optionally "pair_interval", "max_time_offset" (s), "estimate_time_offset",
///   "estimate_gyro_bias" (booleans), "initial_time_offset_ns", "prior_translation" ([x, y, z] m)}.
/// - "camera_intrinsics": {"sensor": "camera_front", "board": {"inner_corners_x": 9,
///   "inner_corners_y": 6, "square_size": 0.05}, "images": [{"data": base64 of a PNG / JPEG /
///   any format OpenCV reads (8-bit gray or colour), "timestamp_ns": optional}, ...], optionally
///   "model" ("radtan" or "equidistant"), "estimate_k3", "max_views"}.
/// Bad values name their field, e.g. "images[3].data".
ApiResult<CalibrateRequest> parse_calibrate(const std::string& body);

/// "tx ty tz qx qy qz qw" lines with the timestamp in seconds (TUM format).
std::string poses_to_tum(const std::vector<msgs::PoseEstimate>& poses);
/// `{"poses": [pose_to_json of each], "next_after": ns or null}` as text, written directly
/// (a page of 100 poses with covariances is ~95 KB: building it as a json value took 5x longer).
std::string trajectory_page_to_json(const std::vector<msgs::PoseEstimate>& poses, std::optional<Timestamp> next_after);

}  // namespace hanzo::fusion::service::detail
