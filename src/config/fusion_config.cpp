#include "hanzo/fusion/config/fusion_config.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <utility>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include "hanzo/fusion/core/enum_names.hpp"

namespace hanzo::fusion::config {
namespace {

constexpr EnumNames<FrontendType, 4> kFrontendNames{
    {{FrontendType::kEkf, "ekf"}, {FrontendType::kUkf, "ukf"}, {FrontendType::kParticle, "particle"}, {FrontendType::kMsckf, "msckf"}}};

constexpr EnumNames<SensorModality, 7> kModalityNames{{{SensorModality::kImu, "imu"},
                                                                                    {SensorModality::kLidar, "lidar"},
                                                                                    {SensorModality::kCamera, "camera"},
                                                                                    {SensorModality::kGnss, "gnss"},
                                                                                    {SensorModality::kWheelOdometry, "wheel_odometry"},
                                                                                    {SensorModality::kRadar, "radar"},
                                                                                    {SensorModality::kRange, "range"}}};

// Name prefixes that imply a modality.
constexpr std::array<std::pair<std::string_view, SensorModality>, 11> kModalityPrefixes{{{"imu", SensorModality::kImu},
                                                                                       {"lidar", SensorModality::kLidar},
                                                                                       {"camera", SensorModality::kCamera},
                                                                                       {"gnss", SensorModality::kGnss},
                                                                                       {"gps", SensorModality::kGnss},
                                                                                       {"wheel", SensorModality::kWheelOdometry},
                                                                                       {"odom", SensorModality::kWheelOdometry},
                                                                                       {"radar", SensorModality::kRadar},
                                                                                       {"range", SensorModality::kRange},
                                                                                       {"sonar", SensorModality::kRange},
                                                                                       {"ultrasonic", SensorModality::kRange}}};

constexpr EnumNames<MatcherType, 2> kMatcherNames{{{MatcherType::kRatio, "ratio"}, {MatcherType::kLearned, "learned"}}};
constexpr EnumNames<PlaceRecognitionType, 2> kPlaceRecognitionNames{{{PlaceRecognitionType::kBow, "bow"}, {PlaceRecognitionType::kLearned, "learned"}}};

Status non_negative(double value, std::string_view field) {
  if (!std::isfinite(value) || value < 0.0) {
    return Error{fmt::format("FusionConfig.{}: {} (expected a finite value >= 0)", field, value), std::string(field)};
  }
  return ok_status();
}

}  // namespace

std::string_view to_string(FrontendType type) { return enum_name(kFrontendNames, type); }
std::optional<FrontendType> frontend_type_from_string(std::string_view name) { return enum_from_name(kFrontendNames, name); }
std::string_view to_string(SensorModality modality) { return enum_name(kModalityNames, modality); }
std::string_view to_string(MatcherType type) { return enum_name(kMatcherNames, type); }
std::string_view to_string(PlaceRecognitionType type) { return enum_name(kPlaceRecognitionNames, type); }

const std::vector<std::string_view>& feature_type_names() {
  static const std::vector<std::string_view> names{"orb", "aliked-t16", "aliked-n16", "aliked-n16rot", "aliked-n32", "alike-t", "alike-s", "alike-n", "alike-l"};
  return names;
}

Status validate(const FeatureSelection& features, const std::string& field) {
  const std::vector<std::string_view>& names = feature_type_names();
  if (std::find(names.begin(), names.end(), features.type) == names.end()) {
    return Error{fmt::format("{}: unknown type '{}' (expected {})", field, features.type, fmt::join(names, ", ")), field};
  }
  if (!features.learned() && !features.model.empty()) return Error{fmt::format("{}: ORB takes no model (the learned types do)", field), field};
  return ok_status();
}

SensorModality modality_of(const msgs::SensorMessage& message) {
  struct Modality {
    SensorModality operator()(const msgs::ImuMessage&) const { return SensorModality::kImu; }
    SensorModality operator()(const msgs::PointCloudMessage&) const { return SensorModality::kLidar; }
    SensorModality operator()(const msgs::ImageMessage&) const { return SensorModality::kCamera; }
    SensorModality operator()(const msgs::GnssMessage&) const { return SensorModality::kGnss; }
    SensorModality operator()(const msgs::WheelOdometryMessage&) const { return SensorModality::kWheelOdometry; }
    SensorModality operator()(const msgs::RadarMessage&) const { return SensorModality::kRadar; }
    SensorModality operator()(const msgs::RangeMessage&) const { return SensorModality::kRange; }
    SensorModality operator()(const msgs::DetectionsMessage&) const { return SensorModality::kCamera; }  // a camera's detections
  };
  return std::visit(Modality{}, message);
}
std::optional<SensorModality> sensor_modality_from_string(std::string_view name) { return enum_from_name(kModalityNames, name); }

std::optional<SensorModality> infer_modality(std::string_view sensor_name) {
  for (const auto& [prefix, modality] : kModalityPrefixes) {
    if (sensor_name.starts_with(prefix)) return modality;
  }
  return std::nullopt;
}

const std::vector<std::pair<std::string_view, SensorModality>>& sensor_driver_types() {
  static const std::vector<std::pair<std::string_view, SensorModality>> types = {{"velodyne", SensorModality::kLidar},
                                                                                 {"ouster", SensorModality::kLidar},
                                                                                 {"ouster_imu", SensorModality::kImu},
                                                                                 {"hesai", SensorModality::kLidar},
                                                                                 {"nmea", SensorModality::kGnss},
                                                                                 {"xsens", SensorModality::kImu}};
  return types;
}

double SensorConfig::effective_timeout_s() const {
  if (fusion.timeout_s > 0.0) return fusion.timeout_s;
  return std::max(0.1, 5.0 / rate_hz);
}

const SensorConfig* FusionConfig::find_sensor(std::string_view name) const {
  for (const SensorConfig& sensor : sensors) {
    if (sensor.name == name) return &sensor;
  }
  return nullptr;
}

Status validate(const FusionConfig& config) {
  const FrontendConfig& frontend = config.frontend;
  if (!std::isfinite(frontend.predict_rate_hz) || frontend.predict_rate_hz <= 0.0) {
    return Error{fmt::format("FusionConfig.frontend.predict_rate_hz: {} (expected > 0 Hz)", frontend.predict_rate_hz),
                 "frontend.predict_rate_hz"};
  }
  const CovarianceConfig& covariance = frontend.covariance;
  for (int i = 0; i < 3; ++i) {
    if (Status s = non_negative(covariance.initial_position[i], "frontend.covariance.initial_position"); !s) return s;
    if (Status s = non_negative(covariance.initial_orientation[i], "frontend.covariance.initial_orientation"); !s) return s;
    if (Status s = non_negative(covariance.initial_velocity[i], "frontend.covariance.initial_velocity"); !s) return s;
  }
  for (const auto& [value, field] : {std::pair<double, std::string_view>{covariance.process_noise_accel, "frontend.covariance.process_noise_accel"},
                                     {covariance.process_noise_gyro, "frontend.covariance.process_noise_gyro"},
                                     {covariance.accel_bias_random_walk, "frontend.covariance.accel_bias_random_walk"},
                                     {covariance.gyro_bias_random_walk, "frontend.covariance.gyro_bias_random_walk"}}) {
    if (Status s = non_negative(value, field); !s) return s;
  }
  if (!(frontend.gate_probability > 0.0 && frontend.gate_probability <= 1.0)) {
    return Error{fmt::format("FusionConfig.frontend.gate_probability: {} (expected a probability in (0, 1])", frontend.gate_probability),
                 "frontend.gate_probability"};
  }
  if (Status s = non_negative(frontend.lag_window_s, "frontend.lag_window"); !s) return s;
  if (Status s = non_negative(frontend.gate_recovery_s, "frontend.gate_recovery"); !s) return s;
  for (const auto& [value, field] : {std::pair<double, std::string_view>{frontend.max_future_s, "frontend.max_future"},
                                     {frontend.static_alignment_s, "frontend.static_alignment"},
                                     {frontend.keyframe_interval(), "frontend.keyframe_interval"}}) {
    if (!std::isfinite(value) || value <= 0.0) {
      return Error{fmt::format("FusionConfig.{}: {} (expected > 0 s)", field, value), std::string(field)};
    }
  }
  for (const auto& [value, field] : {std::pair<double, std::string_view>{frontend.motion_model.acceleration_noise, "frontend.motion_model.acceleration_noise"},
                                     {frontend.motion_model.angular_acceleration_noise, "frontend.motion_model.angular_acceleration_noise"}}) {
    if (!std::isfinite(value) || value <= 0.0) {
      return Error{fmt::format("FusionConfig.{}: {} (expected > 0)", field, value), std::string(field)};
    }
  }
  if (frontend.datum) {
    if (Status s = validate(*frontend.datum); !s) return Error{"FusionConfig.frontend.datum: " + s.error().message, "frontend.datum"};
  }
  const MappingConfig& mapping = config.mapping;
  for (const auto& [value, field] : {std::pair<double, std::string_view>{mapping.lidar_voxel, "mapping.lidar_voxel"},
                                     {mapping.lidar_source_voxel, "mapping.lidar_source_voxel"},
                                     {mapping.lidar_max_range, "mapping.lidar_max_range"},
                                     {mapping.map_voxel, "mapping.map_voxel"},
                                     {mapping.occupancy_resolution, "mapping.occupancy_resolution"},
                                     {mapping.loop_min_travel, "mapping.loop_min_travel"},
                                     {mapping.loop_search_radius, "mapping.loop_search_radius"},
                                     {mapping.loop_max_rmse, "mapping.loop_max_rmse"}}) {
    if (!std::isfinite(value) || value <= 0.0) return Error{fmt::format("FusionConfig.{}: {} (expected > 0)", field, value), std::string(field)};
  }
  if (Status s = non_negative(mapping.keyframe_distance, "mapping.keyframe_distance"); !s) return s;
  if (Status s = non_negative(mapping.keyframe_angle, "mapping.keyframe_angle"); !s) return s;
  if (mapping.visual_inertial_window < 0) {
    return Error{fmt::format("FusionConfig.mapping.visual_inertial_window: {} (expected >= 0)", mapping.visual_inertial_window), "mapping.visual_inertial_window"};
  }
  const SplatMappingConfig& splats = mapping.splats;
  if (splats.image_width < 16 || splats.steps_per_view < 1 || !(splats.cpu_share > 0.0 && splats.cpu_share <= 1.0) || splats.max_gaussians < 1000) {
    return Error{fmt::format("FusionConfig.mapping.splats: image_width {} (>= 16), steps_per_view {} (>= 1), cpu_share {} (in (0, 1]), max_gaussians {} (>= 1000)",
                             splats.image_width, splats.steps_per_view, splats.cpu_share, splats.max_gaussians),
                 "mapping.splats"};
  }
  if (Status s = validate(config.vision.features, "vision.features"); !s) return with_context(s, "FusionConfig");
  std::set<std::string_view> names;
  std::set<std::string_view> topics;
  for (const SensorConfig& sensor : config.sensors) {
    const std::string field = fmt::format("sensors.{}", sensor.name);
    if (sensor.name.empty()) return Error{"FusionConfig.sensors: a sensor has an empty name", "sensors"};
    if (!names.insert(sensor.name).second) return Error{fmt::format("FusionConfig.{}: duplicate sensor name", field), field};
    if (sensor.topic.empty()) return Error{fmt::format("FusionConfig.{}.topic: empty", field), field + ".topic"};
    if (!topics.insert(sensor.topic).second) {
      return Error{fmt::format("FusionConfig.{}.topic: '{}' is used by another sensor", field, sensor.topic), field + ".topic"};
    }
    if (!std::isfinite(sensor.rate_hz) || sensor.rate_hz <= 0.0) {
      return Error{fmt::format("FusionConfig.{}.rate: {} (expected > 0 Hz)", field, sensor.rate_hz), field + ".rate"};
    }
    if (sensor.body_frame.empty()) return Error{fmt::format("FusionConfig.{}.body_frame: empty", field), field + ".body_frame"};
    if (sensor.features) {
      if (sensor.modality != SensorModality::kCamera) return Error{fmt::format("FusionConfig.{}.features: applies to camera sensors only", field), field + ".features"};
      if (Status s = validate(*sensor.features, field + ".features"); !s) return with_context(s, "FusionConfig");
    }
    const SensorFusionOptions& o = sensor.fusion;
    if (Status s = non_negative(o.timeout_s, field + ".timeout"); !s) return s;
    for (const auto& [value, key] : {std::pair<double, std::string_view>{o.orientation_noise, "orientation_noise"},
                                     {o.speed_noise, "speed_noise"}, {o.yaw_rate_noise, "yaw_rate_noise"},
                                     {o.lateral_speed_noise, "lateral_speed_noise"}, {o.velocity_noise, "velocity_noise"}}) {
      if (!std::isfinite(value) || value <= 0.0) {
        return Error{fmt::format("FusionConfig.{}.{}: {} (expected a standard deviation > 0)", field, key, value), field + "." + std::string(key)};
      }
    }
  }
  return ok_status();
}

}  // namespace hanzo::fusion::config
