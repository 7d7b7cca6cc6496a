// POST /v1/calibrate: its request body (motion or camera procedure) and the JSON of the results.
#include <algorithm>
#include <cmath>
#include <cstring>

#include <fmt/format.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "hanzo/fusion/core/base64.hpp"
#include "json_codec.hpp"

namespace hanzo::fusion::service {

using nlohmann::json;

namespace detail {
namespace {

ApiError invalid(const std::string& field, const std::string& message) {
  return {ErrorCode::kInvalidArgument, fmt::format("{}: {}", field, message), field};
}

// Rows of `width` finite numbers, the first a time in seconds.
ApiResult<std::vector<std::vector<double>>> rows(const json& object, const std::string& key, std::size_t width) {
  const json& value = object.at(key);
  if (!value.is_array()) return invalid(key, fmt::format("expected an array of rows of {} numbers", width));
  std::vector<std::vector<double>> out;
  out.reserve(value.size());
  for (std::size_t i = 0; i < value.size(); ++i) {
    const std::string field = fmt::format("{}[{}]", key, i);
    const json& row = value[i];
    if (!row.is_array() || row.size() != width) return invalid(field, fmt::format("expected {} numbers", width));
    std::vector<double> numbers;
    for (const json& element : row) {
      if (!element.is_number() || !std::isfinite(element.get<double>())) return invalid(field, "expected finite numbers");
      numbers.push_back(element.get<double>());
    }
    out.push_back(std::move(numbers));
  }
  return out;
}

// TUM rows [t, x, y, z, qx, qy, qz, qw].
ApiResult<std::vector<calib::StampedPose>> pose_rows(const json& object, const std::string& key) {
  auto parsed = rows(object, key, 8);
  if (!parsed) return parsed.error();
  std::vector<calib::StampedPose> poses;
  for (std::size_t i = 0; i < parsed->size(); ++i) {
    const std::vector<double>& row = parsed.value()[i];
    const Eigen::Quaterniond q(row[7], row[4], row[5], row[6]);
    if (std::abs(q.norm() - 1.0) > 1e-3) {
      return invalid(fmt::format("{}[{}]", key, i), fmt::format("quaternion (qx, qy, qz, qw) has norm {}, not 1", q.norm()));
    }
    poses.push_back({Timestamp::from_seconds(row[0]), SE3(SO3(q.normalized()), Eigen::Vector3d(row[1], row[2], row[3]))});
  }
  return poses;
}

ApiResult<MotionCalibrateRequest> parse_motion_calibrate(const json& object) {
  if (auto keys = check_keys(object, {"procedure", "sensor", "sensor_poses", "body_poses", "gyro", "pair_interval", "max_time_offset",
                                      "estimate_time_offset", "initial_time_offset_ns", "estimate_gyro_bias", "prior_translation"});
      !keys) {
    return keys.error();
  }
  MotionCalibrateRequest request;
  calib::MotionCalibrationInput& input = request.input;
  calib::MotionCalibrationConfig& config = request.config;
  if (!object.contains("sensor") || !object["sensor"].is_string()) return invalid("sensor", "expected the sensor's name");
  input.sensor = object["sensor"].get<std::string>();
  if (!object.contains("sensor_poses")) return invalid("sensor_poses", "missing (the sensor's own odometry, TUM rows)");
  auto sensor_poses = pose_rows(object, "sensor_poses");
  if (!sensor_poses) return sensor_poses.error();
  input.sensor_poses = std::move(sensor_poses).value();
  if (object.contains("body_poses") == object.contains("gyro")) {
    return invalid("body_poses", "give the body's motion as body_poses (TUM rows) or gyro ([t, wx, wy, wz] rows), one of them");
  }
  if (object.contains("body_poses")) {
    auto body_poses = pose_rows(object, "body_poses");
    if (!body_poses) return body_poses.error();
    input.body_poses = std::move(body_poses).value();
  } else {
    auto gyro = rows(object, "gyro", 4);
    if (!gyro) return gyro.error();
    for (const std::vector<double>& row : gyro.value()) {
      input.body_gyro.push_back({Timestamp::from_seconds(row[0]), Eigen::Vector3d(row[1], row[2], row[3])});
    }
  }
  for (const auto& [key, target] : {std::pair<const char*, double*>{"pair_interval", &config.pair_interval},
                                    std::pair<const char*, double*>{"max_time_offset", &config.max_time_offset}}) {
    if (!object.contains(key)) continue;
    if (!object[key].is_number() || !std::isfinite(object[key].get<double>()) || object[key].get<double>() <= 0.0) {
      return invalid(key, "expected a positive number of seconds");
    }
    *target = object[key].get<double>();
  }
  config.time_offset_step = std::min(config.time_offset_step, config.max_time_offset);
  for (const auto& [key, target] : {std::pair<const char*, bool*>{"estimate_time_offset", &config.estimate_time_offset},
                                    std::pair<const char*, bool*>{"estimate_gyro_bias", &config.estimate_gyro_bias}}) {
    if (!object.contains(key)) continue;
    if (!object[key].is_boolean()) return invalid(key, "expected true or false");
    *target = object[key].get<bool>();
  }
  if (object.contains("initial_time_offset_ns")) {
    if (!object["initial_time_offset_ns"].is_number_integer()) return invalid("initial_time_offset_ns", "expected an integer");
    config.initial_time_offset = Duration::from_nanoseconds(object["initial_time_offset_ns"].get<int64_t>());
  }
  if (object.contains("prior_translation")) {
    const json& prior = object["prior_translation"];
    if (!prior.is_array() || prior.size() != 3 ||
        !std::all_of(prior.begin(), prior.end(), [](const json& v) { return v.is_number() && std::isfinite(v.get<double>()); })) {
      return invalid("prior_translation", "expected 3 finite numbers (m, body frame)");
    }
    config.prior_translation = Eigen::Vector3d(prior[0].get<double>(), prior[1].get<double>(), prior[2].get<double>());
  }
  return request;
}

// An image file's bytes (base64) as a mono8 or bgr8 image message.
ApiResult<msgs::ImageMessage> decode_image(const json& entry, const std::string& field, std::size_t index) {
  if (!entry.is_object()) return invalid(field, "expected {\"data\": base64 of an image file, \"timestamp_ns\": optional}");
  if (auto keys = check_keys(entry, {"data", "timestamp_ns"}); !keys) {
    return invalid(field + "." + keys.error().field, keys.error().message);
  }
  if (!entry.contains("data") || !entry["data"].is_string()) return invalid(field + ".data", "expected base64 text of an image file");
  auto bytes = base64_decode(entry["data"].get_ref<const std::string&>());
  if (!bytes) return invalid(field + ".data", bytes.error().message);
  cv::Mat image;
  try {
    image = cv::imdecode(bytes.value(), cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& exception) {
    return invalid(field + ".data", fmt::format("not an image file ({})", exception.what()));
  }
  if (image.empty()) return invalid(field + ".data", fmt::format("not an image file OpenCV can read ({} bytes)", bytes->size()));
  if (image.depth() != CV_8U) return invalid(field + ".data", "expected 8-bit samples (a 16-bit or float image is no camera frame here)");
  if (image.channels() == 4) cv::cvtColor(image, image, cv::COLOR_BGRA2BGR);
  if (image.channels() != 1 && image.channels() != 3) return invalid(field + ".data", fmt::format("{} channels: expected gray or colour", image.channels()));
  msgs::ImageMessage message;
  message.timestamp = Timestamp::from_nanoseconds(static_cast<int64_t>(index));
  if (entry.contains("timestamp_ns")) {
    if (!entry["timestamp_ns"].is_number_integer()) return invalid(field + ".timestamp_ns", "expected an integer");
    message.timestamp = Timestamp::from_nanoseconds(entry["timestamp_ns"].get<int64_t>());
  }
  message.width = static_cast<uint32_t>(image.cols);
  message.height = static_cast<uint32_t>(image.rows);
  message.encoding = image.channels() == 1 ? msgs::ImageEncoding::kMono8 : msgs::ImageEncoding::kBgr8;
  const std::size_t row_bytes = static_cast<std::size_t>(image.cols) * static_cast<std::size_t>(image.channels());
  message.data.resize(row_bytes * static_cast<std::size_t>(image.rows));
  for (int row = 0; row < image.rows; ++row) std::memcpy(message.data.data() + row_bytes * static_cast<std::size_t>(row), image.ptr(row), row_bytes);
  return message;
}

ApiResult<CameraCalibrateRequest> parse_camera_calibrate(const json& object) {
  if (auto keys = check_keys(object, {"procedure", "sensor", "board", "images", "model", "estimate_k3", "max_views"}); !keys) {
    return keys.error();
  }
  CameraCalibrateRequest request;
  calib::CameraCalibrationConfig& config = request.config;
  if (!object.contains("sensor") || !object["sensor"].is_string()) return invalid("sensor", "expected the camera's name");
  request.sensor = object["sensor"].get<std::string>();
  if (!object.contains("board") || !object["board"].is_object()) {
    return invalid("board", "expected {\"inner_corners_x\": 9, \"inner_corners_y\": 6, \"square_size\": 0.05}");
  }
  const json& board = object["board"];
  if (auto keys = check_keys(board, {"inner_corners_x", "inner_corners_y", "square_size"}); !keys) {
    return invalid("board." + keys.error().field, keys.error().message);
  }
  for (const auto& [key, target] : {std::pair<const char*, int*>{"inner_corners_x", &config.target.inner_corners_x},
                                    std::pair<const char*, int*>{"inner_corners_y", &config.target.inner_corners_y}}) {
    if (!board.contains(key) || !board[key].is_number_integer() || board[key].get<int64_t>() < 2 || board[key].get<int64_t>() > 100) {
      return invalid(fmt::format("board.{}", key), "expected the count of inner corners (where four squares meet), 2-100");
    }
    *target = board[key].get<int>();
  }
  if (!board.contains("square_size") || !board["square_size"].is_number() || !std::isfinite(board["square_size"].get<double>()) ||
      board["square_size"].get<double>() <= 0.0) {
    return invalid("board.square_size", "expected the edge of a square in metres (> 0)");
  }
  config.target.square_size = board["square_size"].get<double>();
  if (object.contains("model")) {
    const std::optional<msgs::DistortionType> model =
        object["model"].is_string() ? msgs::distortion_type_from_string(object["model"].get<std::string>()) : std::nullopt;
    if (!model || (*model != msgs::DistortionType::kRadtan && *model != msgs::DistortionType::kEquidistant)) {
      return invalid("model", "expected \"radtan\" or \"equidistant\"");
    }
    config.model = *model;
  }
  if (object.contains("estimate_k3")) {
    if (!object["estimate_k3"].is_boolean()) return invalid("estimate_k3", "expected true or false");
    config.estimate_k3 = object["estimate_k3"].get<bool>();
  }
  if (object.contains("max_views")) {
    if (!object["max_views"].is_number_integer() || object["max_views"].get<int64_t>() < static_cast<int64_t>(config.min_views)) {
      return invalid("max_views", fmt::format("expected an integer >= {}", config.min_views));
    }
    config.max_views = object["max_views"].get<std::size_t>();
  }
  if (!object.contains("images") || !object["images"].is_array() || object["images"].empty()) {
    return invalid("images", "expected a non-empty array of {\"data\": base64 of an image file}");
  }
  const json& images = object["images"];
  for (std::size_t i = 0; i < images.size(); ++i) {
    auto image = decode_image(images[i], fmt::format("images[{}]", i), i);
    if (!image) return image.error();
    request.images.push_back(std::move(image).value());
  }
  return request;
}

}  // namespace

ApiResult<CalibrateRequest> parse_calibrate(const std::string& body) {
  auto document = parse_object(body);
  if (!document) return document.error();
  const json& object = document.value();
  const std::string procedure = object.contains("procedure") && object["procedure"].is_string() ? object["procedure"].get<std::string>() : "";
  if (!object.contains("procedure") || procedure == "motion") {
    auto motion = parse_motion_calibrate(object);
    if (!motion) return motion.error();
    return CalibrateRequest{std::move(motion).value()};
  }
  if (procedure == "camera_intrinsics") {
    auto camera = parse_camera_calibrate(object);
    if (!camera) return camera.error();
    return CalibrateRequest{std::move(camera).value()};
  }
  return invalid("procedure", "expected \"motion\" (hand-eye from motion, the default) or \"camera_intrinsics\" (a checkerboard)");
}

}  // namespace detail
}  // namespace hanzo::fusion::service
