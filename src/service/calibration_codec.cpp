// POST /v1/calibrate: its request body and the JSON of a motion calibration's result.
#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "hanzo/fusion/service/motion_calibration_json.hpp"
#include "json_codec.hpp"

namespace hanzo::fusion::service {

using nlohmann::json;

json motion_calibration_to_json(const calib::MotionCalibrationSummary& summary) {
  const auto vector = [](const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); };
  const calib::SensorCalibration& result = summary.calibration;
  const Eigen::Vector4d& q = result.rotation_wxyz;
  return {{"sensor", result.sensor},
          {"rotation_wxyz", json::array({q[0], q[1], q[2], q[3]})},
          {"translation", vector(result.translation)},
          {"time_offset_ns", result.time_offset.nanoseconds()},
          {"translation_estimated", summary.translation_estimated},
          {"unobservable_translation_axis",
           summary.unobservable_translation_axis ? vector(*summary.unobservable_translation_axis) : json(nullptr)},
          {"gyro_bias", vector(summary.gyro_bias)},
          {"pairs", summary.pairs},
          {"rotation_pairs", summary.rotation_pairs},
          {"outlier_pairs", summary.outlier_pairs},
          {"rotation_residual_rms_deg", summary.rotation_residual_rms_deg},
          {"translation_residual_rms_m", summary.translation_residual_rms_m},
          {"rotation_axis_spread", summary.rotation_axis_spread},
          {"translation_observability", summary.translation_observability},
          {"calibration_yaml", calib::to_yaml(calib::Calibration{{result}})}};
}

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

}  // namespace

ApiResult<CalibrateRequest> parse_calibrate(const std::string& body) {
  auto document = parse_object(body);
  if (!document) return document.error();
  const json& object = document.value();
  if (auto keys = check_keys(object, {"sensor", "sensor_poses", "body_poses", "gyro", "pair_interval", "max_time_offset",
                                      "estimate_time_offset", "initial_time_offset_ns", "estimate_gyro_bias", "prior_translation"});
      !keys) {
    return keys.error();
  }
  CalibrateRequest request;
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

}  // namespace detail
}  // namespace hanzo::fusion::service
