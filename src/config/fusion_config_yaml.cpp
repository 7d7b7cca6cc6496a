// Reading and writing the fusion configuration YAML (layout: fusion_config.hpp).

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <algorithm>
#include <array>

#include <fmt/ranges.h>

#include <fmt/format.h>

#include "hanzo/fusion/config/fusion_config.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"

namespace hanzo::fusion::config {
namespace {


Result<double> positive_rate(const YamlValue& value) {
  Result<double> rate = value.as_double();
  if (!rate) return rate;
  if (*rate <= 0.0) return value.error(fmt::format("expected a positive rate in Hz, got {}", *rate));
  return rate;
}

Result<CovarianceConfig> parse_covariance(const YamlValue& node) {
  CovarianceConfig covariance;
  if (!node.present()) return covariance;
  HANZO_RETURN_IF_ERROR(node.check_keys({"initial_position", "initial_orientation", "initial_velocity", "process_noise_accel",
                                  "process_noise_gyro", "accel_bias_random_walk", "gyro_bias_random_walk"}));
  HANZO_ASSIGN_OR_RETURN(covariance.initial_position, yaml::vector3_or(node["initial_position"], covariance.initial_position, "(x, y, z)"));
  HANZO_ASSIGN_OR_RETURN(covariance.initial_orientation,
                 yaml::vector3_or(node["initial_orientation"], covariance.initial_orientation, "(roll, pitch, yaw)"));
  HANZO_ASSIGN_OR_RETURN(covariance.initial_velocity, yaml::vector3_or(node["initial_velocity"], covariance.initial_velocity, "(x, y, z)"));
  HANZO_ASSIGN_OR_RETURN(covariance.process_noise_accel, yaml::non_negative_or(node["process_noise_accel"], covariance.process_noise_accel));
  HANZO_ASSIGN_OR_RETURN(covariance.process_noise_gyro, yaml::non_negative_or(node["process_noise_gyro"], covariance.process_noise_gyro));
  HANZO_ASSIGN_OR_RETURN(covariance.accel_bias_random_walk,
                 yaml::non_negative_or(node["accel_bias_random_walk"], covariance.accel_bias_random_walk));
  HANZO_ASSIGN_OR_RETURN(covariance.gyro_bias_random_walk, yaml::non_negative_or(node["gyro_bias_random_walk"], covariance.gyro_bias_random_walk));
  return covariance;
}

Result<double> positive_seconds(const YamlValue& value) {
  Result<double> seconds = value.as_double();
  if (!seconds) return seconds;
  if (*seconds <= 0.0) return value.error(fmt::format("expected a positive duration in seconds, got {}", *seconds));
  return seconds;
}

Result<bool> bool_or(const YamlValue& value, bool fallback) {
  if (!value.present()) return fallback;
  return value.as_bool();
}

// A noise standard deviation: finite and > 0 (a zero noise makes the update singular).
Result<double> noise_or(const YamlValue& value, double fallback) {
  double sigma = 0.0;
  HANZO_ASSIGN_OR_RETURN(sigma, yaml::non_negative_or(value, fallback));
  if (sigma <= 0.0) return value.error("expected a standard deviation > 0");
  return sigma;
}

Result<GeodeticPoint> parse_datum(const YamlValue& node) {
  HANZO_RETURN_IF_ERROR(node.check_keys({"latitude", "longitude", "altitude"}));
  GeodeticPoint datum;
  HANZO_ASSIGN_OR_RETURN(datum.latitude_deg, node["latitude"].as_double());
  HANZO_ASSIGN_OR_RETURN(datum.longitude_deg, node["longitude"].as_double());
  if (node["altitude"].present()) HANZO_ASSIGN_OR_RETURN(datum.altitude_m, node["altitude"].as_double());
  if (Status valid = validate(datum); !valid) return node.error(valid.error().message);
  return datum;
}

Result<FrontendConfig> parse_frontend(const YamlValue& node) {
  FrontendConfig frontend;
  if (!node.present()) return frontend;
  HANZO_RETURN_IF_ERROR(node.check_keys({"type", "predict_rate", "covariance", "gate_probability", "lag_window", "max_future",
                                         "static_alignment", "planar", "zero_velocity_updates", "datum", "ukf", "particle_filter",
                                         "keyframe_interval", "gate_recovery", "motion_model", "initial_yaw"}));
  if (node["type"].present()) {
    Result<std::string> name = node["type"].as_string();
    if (!name) return name.error();
    const std::optional<FrontendType> type = frontend_type_from_string(*name);
    if (!type) return node["type"].error(fmt::format("expected ekf, ukf, particle or msckf, got '{}'", *name));
    frontend.type = *type;
  }
  if (node["predict_rate"].present()) HANZO_ASSIGN_OR_RETURN(frontend.predict_rate_hz, positive_rate(node["predict_rate"]));
  HANZO_ASSIGN_OR_RETURN(frontend.covariance, parse_covariance(node["covariance"]));
  if (const YamlValue gate = node["gate_probability"]; gate.present()) {
    HANZO_ASSIGN_OR_RETURN(frontend.gate_probability, gate.as_double());
    if (!(frontend.gate_probability > 0.0 && frontend.gate_probability <= 1.0)) {
      return gate.error(fmt::format("expected a probability in (0, 1], got {}", frontend.gate_probability));
    }
  }
  HANZO_ASSIGN_OR_RETURN(frontend.lag_window_s, yaml::non_negative_or(node["lag_window"], frontend.lag_window_s));
  HANZO_ASSIGN_OR_RETURN(frontend.gate_recovery_s, yaml::non_negative_or(node["gate_recovery"], frontend.gate_recovery_s));
  if (node["max_future"].present()) HANZO_ASSIGN_OR_RETURN(frontend.max_future_s, positive_seconds(node["max_future"]));
  if (node["static_alignment"].present()) HANZO_ASSIGN_OR_RETURN(frontend.static_alignment_s, positive_seconds(node["static_alignment"]));
  if (node["keyframe_interval"].present()) HANZO_ASSIGN_OR_RETURN(frontend.keyframe_interval_s, positive_seconds(node["keyframe_interval"]));
  HANZO_ASSIGN_OR_RETURN(frontend.planar, bool_or(node["planar"], frontend.planar));
  HANZO_ASSIGN_OR_RETURN(frontend.zero_velocity_updates, bool_or(node["zero_velocity_updates"], frontend.zero_velocity_updates));
  if (node["datum"].present()) HANZO_ASSIGN_OR_RETURN(frontend.datum, parse_datum(node["datum"]));
  if (const YamlValue yaw = node["initial_yaw"]; yaw.present()) {
    HANZO_ASSIGN_OR_RETURN(frontend.initial_yaw, yaw.as_double());
    if (!(std::abs(*frontend.initial_yaw) <= 2.0 * M_PI)) return yaw.error(fmt::format("expected radians in [-2 pi, 2 pi], got {}", *frontend.initial_yaw));
  }
  if (const YamlValue ukf = node["ukf"]; ukf.present()) {
    HANZO_RETURN_IF_ERROR(ukf.check_keys({"alpha", "beta", "kappa"}));
    if (ukf["alpha"].present()) HANZO_ASSIGN_OR_RETURN(frontend.ukf.alpha, ukf["alpha"].as_double());
    if (!(frontend.ukf.alpha > 0.0 && frontend.ukf.alpha <= 1.0)) return ukf["alpha"].error("expected a value in (0, 1]");
    HANZO_ASSIGN_OR_RETURN(frontend.ukf.beta, yaml::non_negative_or(ukf["beta"], frontend.ukf.beta));
    if (ukf["kappa"].present()) HANZO_ASSIGN_OR_RETURN(frontend.ukf.kappa, ukf["kappa"].as_double());
    if (frontend.ukf.kappa <= -18.0) return ukf["kappa"].error("expected a value > -18 (18 + kappa must be positive)");
  }
  if (const YamlValue motion = node["motion_model"]; motion.present()) {
    HANZO_RETURN_IF_ERROR(motion.check_keys({"acceleration_noise", "angular_acceleration_noise"}));
    MotionModelSettings& model = frontend.motion_model;
    HANZO_ASSIGN_OR_RETURN(model.acceleration_noise, yaml::positive_or(motion["acceleration_noise"], model.acceleration_noise));
    HANZO_ASSIGN_OR_RETURN(model.angular_acceleration_noise,
                           yaml::positive_or(motion["angular_acceleration_noise"], model.angular_acceleration_noise));
  }
  if (const YamlValue particles = node["particle_filter"]; particles.present()) {
    HANZO_RETURN_IF_ERROR(particles.check_keys({"particles", "resample_threshold", "seed"}));
    if (particles["particles"].present()) {
      int64_t count = 0;
      HANZO_ASSIGN_OR_RETURN(count, particles["particles"].as_int64());
      if (count < 100 || count > 100000) return particles["particles"].error(fmt::format("expected 100 to 100000 particles, got {}", count));
      frontend.particle_filter.particles = static_cast<int>(count);
    }
    if (particles["resample_threshold"].present()) {
      HANZO_ASSIGN_OR_RETURN(frontend.particle_filter.resample_threshold, particles["resample_threshold"].as_double());
      const double threshold = frontend.particle_filter.resample_threshold;
      if (!(threshold > 0.0 && threshold <= 1.0)) return particles["resample_threshold"].error("expected a fraction in (0, 1]");
    }
    if (particles["seed"].present()) {
      int64_t seed = 0;
      HANZO_ASSIGN_OR_RETURN(seed, particles["seed"].as_int64());
      if (seed < 0) return particles["seed"].error("expected a whole number >= 0");
      frontend.particle_filter.seed = static_cast<uint64_t>(seed);
    }
  }
  return frontend;
}

using yaml::positive_or;

// `splats: true` or `splats: {enabled: true, image_width: 160, ...}`.
Result<SplatMappingConfig> parse_splats(const YamlValue& node) {
  SplatMappingConfig splats;
  if (!node.present()) return splats;
  if (!node.is_map()) {
    HANZO_ASSIGN_OR_RETURN(splats.enabled, node.as_bool());
    return splats;
  }
  HANZO_RETURN_IF_ERROR(node.check_keys({"enabled", "image_width", "steps_per_view", "cpu_share", "max_gaussians"}));
  HANZO_ASSIGN_OR_RETURN(splats.enabled, bool_or(node["enabled"], true));
  HANZO_ASSIGN_OR_RETURN(splats.cpu_share, positive_or(node["cpu_share"], splats.cpu_share));
  if (splats.cpu_share > 1.0) return node["cpu_share"].error(fmt::format("expected a share of one core in (0, 1], got {}", splats.cpu_share));
  for (auto [key, value, least] : {std::tuple{"image_width", &splats.image_width, 16}, std::tuple{"steps_per_view", &splats.steps_per_view, 1},
                                   std::tuple{"max_gaussians", &splats.max_gaussians, 1000}}) {
    const YamlValue& entry = node[key];
    if (!entry.present()) continue;
    int64_t number = 0;
    HANZO_ASSIGN_OR_RETURN(number, entry.as_int64());
    if (number < least || number > 100000000) return entry.error(fmt::format("expected an integer >= {}, got {}", least, number));
    *value = static_cast<int>(number);
  }
  return splats;
}

Result<MappingConfig> parse_mapping(const YamlValue& node) {
  MappingConfig mapping;
  if (!node.present()) return mapping;
  HANZO_RETURN_IF_ERROR(node.check_keys({"enabled", "lidar_voxel", "lidar_source_voxel", "lidar_max_range", "map_voxel",
                                         "occupancy_resolution", "keyframe_distance", "keyframe_angle", "remove_moving_points", "loop_closure",
                                         "loop_min_travel", "loop_search_radius", "loop_max_rmse", "gnss_factors", "gnss_error_correlation", "follow_graph", "velocity_factors", "visual_inertial_window", "splats"}));
  HANZO_ASSIGN_OR_RETURN(mapping.enabled, bool_or(node["enabled"], mapping.enabled));
  HANZO_ASSIGN_OR_RETURN(mapping.lidar_voxel, positive_or(node["lidar_voxel"], mapping.lidar_voxel));
  HANZO_ASSIGN_OR_RETURN(mapping.lidar_source_voxel, positive_or(node["lidar_source_voxel"], mapping.lidar_source_voxel));
  HANZO_ASSIGN_OR_RETURN(mapping.lidar_max_range, positive_or(node["lidar_max_range"], mapping.lidar_max_range));
  HANZO_ASSIGN_OR_RETURN(mapping.map_voxel, positive_or(node["map_voxel"], mapping.map_voxel));
  HANZO_ASSIGN_OR_RETURN(mapping.occupancy_resolution, positive_or(node["occupancy_resolution"], mapping.occupancy_resolution));
  HANZO_ASSIGN_OR_RETURN(mapping.keyframe_distance, yaml::non_negative_or(node["keyframe_distance"], mapping.keyframe_distance));
  HANZO_ASSIGN_OR_RETURN(mapping.keyframe_angle, yaml::non_negative_or(node["keyframe_angle"], mapping.keyframe_angle));
  HANZO_ASSIGN_OR_RETURN(mapping.remove_moving_points, bool_or(node["remove_moving_points"], mapping.remove_moving_points));
  HANZO_ASSIGN_OR_RETURN(mapping.loop_closure, bool_or(node["loop_closure"], mapping.loop_closure));
  HANZO_ASSIGN_OR_RETURN(mapping.loop_min_travel, positive_or(node["loop_min_travel"], mapping.loop_min_travel));
  HANZO_ASSIGN_OR_RETURN(mapping.loop_search_radius, positive_or(node["loop_search_radius"], mapping.loop_search_radius));
  HANZO_ASSIGN_OR_RETURN(mapping.loop_max_rmse, positive_or(node["loop_max_rmse"], mapping.loop_max_rmse));
  HANZO_ASSIGN_OR_RETURN(mapping.gnss_factors, bool_or(node["gnss_factors"], mapping.gnss_factors));
  HANZO_ASSIGN_OR_RETURN(mapping.velocity_factors, bool_or(node["velocity_factors"], mapping.velocity_factors));
  HANZO_ASSIGN_OR_RETURN(mapping.follow_graph, bool_or(node["follow_graph"], mapping.follow_graph));
  HANZO_ASSIGN_OR_RETURN(mapping.gnss_error_correlation, yaml::non_negative_or(node["gnss_error_correlation"], mapping.gnss_error_correlation));
  if (const YamlValue& window = node["visual_inertial_window"]; window.present()) {
    int64_t keyframes = 0;
    HANZO_ASSIGN_OR_RETURN(keyframes, window.as_int64());
    if (keyframes < 0 || keyframes > 1000000) return window.error(fmt::format("expected a number of keyframes >= 0, got {}", keyframes));
    mapping.visual_inertial_window = static_cast<int>(keyframes);
  }
  HANZO_ASSIGN_OR_RETURN(mapping.splats, parse_splats(node["splats"]));
  return mapping;
}

// `features: aliked-t16` or `features: {type: aliked-t16, model: PATH}`.
Result<FeatureSelection> parse_features(const YamlValue& node) {
  FeatureSelection features;
  if (node.is_map()) {
    HANZO_RETURN_IF_ERROR(node.check_keys({"type", "model"}));
    if (node["type"].present()) HANZO_ASSIGN_OR_RETURN(features.type, node["type"].as_string());
    if (node["model"].present()) HANZO_ASSIGN_OR_RETURN(features.model, node["model"].as_string());
  } else {
    HANZO_ASSIGN_OR_RETURN(features.type, node.as_string());
  }
  const std::vector<std::string_view>& names = feature_type_names();
  if (std::find(names.begin(), names.end(), features.type) == names.end()) {
    return (node.is_map() ? node["type"] : node).error(fmt::format("expected {}, got '{}'", fmt::join(names, ", "), features.type));
  }
  if (!features.learned() && !features.model.empty()) return node["model"].error("ORB takes no model (the learned types do)");
  return features;
}

Result<VisionConfig> parse_vision(const YamlValue& node) {
  VisionConfig vision;
  if (!node.present()) return vision;
  HANZO_RETURN_IF_ERROR(node.check_keys({"features", "matcher", "place_recognition", "place_model", "local_mapping_thread", "dynamic_objects", "detector"}));
  if (node["features"].present()) HANZO_ASSIGN_OR_RETURN(vision.features, parse_features(node["features"]));
  if (const YamlValue matcher = node["matcher"]; matcher.present()) {
    std::string name;
    HANZO_ASSIGN_OR_RETURN(name, matcher.as_string());
    if (name == "ratio") vision.matcher = MatcherType::kRatio;
    else if (name == "learned") vision.matcher = MatcherType::kLearned;
    else return matcher.error(fmt::format("expected ratio or learned, got '{}'", name));
  }
  if (const YamlValue place = node["place_recognition"]; place.present()) {
    std::string name;
    HANZO_ASSIGN_OR_RETURN(name, place.as_string());
    if (name == "bow") vision.place_recognition = PlaceRecognitionType::kBow;
    else if (name == "learned") vision.place_recognition = PlaceRecognitionType::kLearned;
    else return place.error(fmt::format("expected bow or learned, got '{}'", name));
  }
  if (node["place_model"].present()) HANZO_ASSIGN_OR_RETURN(vision.place_model, node["place_model"].as_string());
  if (node["local_mapping_thread"].present()) HANZO_ASSIGN_OR_RETURN(vision.local_mapping_thread, node["local_mapping_thread"].as_bool());
  if (const YamlValue dynamic = node["dynamic_objects"]; dynamic.present()) {
    HANZO_RETURN_IF_ERROR(dynamic.check_keys({"classes", "min_score", "margin_px", "wait_for_detections"}));
    DynamicObjectsConfig& objects = vision.dynamic_objects;
    if (const YamlValue classes = dynamic["classes"]; classes.present()) {
      objects.classes.clear();
      for (const YamlValue& element : classes.elements()) {
        std::string name;
        HANZO_ASSIGN_OR_RETURN(name, element.as_string());
        if (name.empty()) return element.error("a class name must not be empty");
        objects.classes.push_back(std::move(name));
      }
    }
    if (dynamic["min_score"].present()) HANZO_ASSIGN_OR_RETURN(objects.min_score, dynamic["min_score"].as_double());
    if (!(objects.min_score >= 0.0 && objects.min_score <= 1.0)) return dynamic["min_score"].error(fmt::format("{} outside [0, 1]", objects.min_score));
    if (dynamic["margin_px"].present()) HANZO_ASSIGN_OR_RETURN(objects.margin_px, dynamic["margin_px"].as_double());
    if (!(objects.margin_px >= 0.0 && objects.margin_px <= 1000.0)) return dynamic["margin_px"].error(fmt::format("{} px: expected 0..1000", objects.margin_px));
    if (dynamic["wait_for_detections"].present()) HANZO_ASSIGN_OR_RETURN(objects.wait_for_detections, dynamic["wait_for_detections"].as_bool());
  }
  if (const YamlValue detector = node["detector"]; detector.present()) {
    // `detector: TYPE` or `detector: {type: TYPE, model: PATH, score_threshold: S}`.
    DetectorSelection& selection = vision.detector;
    if (detector.is_map()) {
      HANZO_RETURN_IF_ERROR(detector.check_keys({"type", "model", "score_threshold"}));
      if (detector["type"].present()) HANZO_ASSIGN_OR_RETURN(selection.type, detector["type"].as_string());
      if (detector["model"].present()) HANZO_ASSIGN_OR_RETURN(selection.model, detector["model"].as_string());
      if (detector["score_threshold"].present()) HANZO_ASSIGN_OR_RETURN(selection.score_threshold, detector["score_threshold"].as_double());
    } else {
      HANZO_ASSIGN_OR_RETURN(selection.type, detector.as_string());
    }
    if (selection.type != "none" && selection.type != "nanodet") return detector.error(fmt::format("type: expected none or nanodet, got '{}'", selection.type));
    if (!(selection.score_threshold > 0.0 && selection.score_threshold < 1.0)) {
      return detector.error(fmt::format("score_threshold: {} outside (0, 1)", selection.score_threshold));
    }
    if (!selection.model.empty() && !selection.enabled()) return detector.error("model: given, but the type is none");
  }
  return vision;
}

// The per-modality fusion keys; each is valid for one modality only.
struct ModalityKey {
  std::string_view key;
  SensorModality modality;
};
constexpr std::array<ModalityKey, 10> kModalityKeys{{{"use_orientation", SensorModality::kImu},
                                                     {"orientation_noise", SensorModality::kImu},
                                                     {"speed_noise", SensorModality::kWheelOdometry},
                                                     {"yaw_rate_noise", SensorModality::kWheelOdometry},
                                                     {"lateral_speed_noise", SensorModality::kWheelOdometry},
                                                     {"use_yaw_rate", SensorModality::kWheelOdometry},
                                                     {"non_holonomic", SensorModality::kWheelOdometry},
                                                     {"min_fix", SensorModality::kGnss},
                                                     {"velocity_noise", SensorModality::kRadar},
                                                     {"timeout", SensorModality::kImu}}};  // timeout: any modality

Result<SensorFusionOptions> parse_fusion_options(const YamlValue& node, SensorModality modality) {
  for (const ModalityKey& entry : kModalityKeys) {
    if (entry.key != "timeout" && node[entry.key].present() && entry.modality != modality) {
      return node[entry.key].error(fmt::format("applies to {} sensors only (this sensor is {})", to_string(entry.modality), to_string(modality)));
    }
  }
  SensorFusionOptions options;
  HANZO_ASSIGN_OR_RETURN(options.timeout_s, yaml::non_negative_or(node["timeout"], options.timeout_s));
  if (const YamlValue angles = node["use_orientation"]; angles.present()) {
    if (!angles.is_sequence()) return angles.error("expected a list of roll, pitch, yaw");
    for (const YamlValue& element : angles.elements()) {
      std::string angle;
      HANZO_ASSIGN_OR_RETURN(angle, element.as_string());
      if (angle == "roll") options.use_orientation[0] = true;
      else if (angle == "pitch") options.use_orientation[1] = true;
      else if (angle == "yaw") options.use_orientation[2] = true;
      else return element.error(fmt::format("expected roll, pitch or yaw, got '{}'", angle));
    }
  }
  HANZO_ASSIGN_OR_RETURN(options.orientation_noise, noise_or(node["orientation_noise"], options.orientation_noise));
  HANZO_ASSIGN_OR_RETURN(options.speed_noise, noise_or(node["speed_noise"], options.speed_noise));
  HANZO_ASSIGN_OR_RETURN(options.yaw_rate_noise, noise_or(node["yaw_rate_noise"], options.yaw_rate_noise));
  HANZO_ASSIGN_OR_RETURN(options.lateral_speed_noise, noise_or(node["lateral_speed_noise"], options.lateral_speed_noise));
  HANZO_ASSIGN_OR_RETURN(options.use_yaw_rate, bool_or(node["use_yaw_rate"], options.use_yaw_rate));
  HANZO_ASSIGN_OR_RETURN(options.non_holonomic, bool_or(node["non_holonomic"], options.non_holonomic));
  if (const YamlValue fix = node["min_fix"]; fix.present()) {
    std::string text;
    HANZO_ASSIGN_OR_RETURN(text, fix.as_string());
    const std::optional<msgs::GnssFixType> type = msgs::gnss_fix_type_from_string(text);
    if (!type || *type == msgs::GnssFixType::kNoFix) return fix.error(fmt::format("expected FIX_2D, FIX_3D, RTK_FLOAT or RTK_FIXED, got '{}'", text));
    options.min_fix = *type;
  }
  HANZO_ASSIGN_OR_RETURN(options.velocity_noise, noise_or(node["velocity_noise"], options.velocity_noise));
  return options;
}

Result<SensorDriverConfig> parse_driver(const YamlValue& node, SensorModality modality) {
  if (!node.is_map()) return node.error("expected a map with type and source (and the driver's files)");
  HANZO_RETURN_IF_ERROR(node.check_keys({"type", "source", "model", "calibration", "firetime", "metadata"}));
  SensorDriverConfig driver;
  for (const auto& [key, field] : {std::pair{"type", &driver.type}, {"source", &driver.source}, {"model", &driver.model},
                                   {"calibration", &driver.calibration}, {"firetime", &driver.firetime}, {"metadata", &driver.metadata}}) {
    if (node[key].present()) HANZO_ASSIGN_OR_RETURN(*field, node[key].as_string());
  }
  const auto& types = sensor_driver_types();
  const auto type = std::find_if(types.begin(), types.end(), [&](const auto& entry) { return entry.first == driver.type; });
  if (type == types.end()) return node["type"].error(fmt::format("expected velodyne, ouster, ouster_imu, hesai, nmea or xsens, got '{}'", driver.type));
  if (type->second != modality) {
    return node["type"].error(fmt::format("a {} driver delivers {} data (this sensor is {})", driver.type, to_string(type->second), to_string(modality)));
  }
  if (driver.source.empty()) return node["source"].error("missing (udp://:PORT, tcp://HOST:PORT or serial:///dev/NAME?baud=N)");
  if (driver.type == "velodyne" && driver.model.empty()) return node["model"].error("missing (VLP-16, VLP-32C, HDL-32E, HDL-64E or VLS-128)");
  if (driver.type == "hesai" && driver.calibration.empty()) return node["calibration"].error("missing (the unit's angle correction CSV)");
  if ((driver.type == "ouster" || driver.type == "ouster_imu") && driver.metadata.empty()) {
    return node["metadata"].error("missing (the sensor's metadata JSON)");
  }
  return driver;
}

Result<SensorConfig> parse_sensor(const std::string& name, const YamlValue& node) {
  SensorConfig sensor;
  sensor.name = name;
  if (!node.is_map()) return node.error("expected a map with topic, rate, body_frame (and optionally type, modality)");
  HANZO_RETURN_IF_ERROR(node.check_keys({"topic", "rate", "body_frame", "type", "modality", "timeout", "use_orientation",
                                         "orientation_noise", "speed_noise", "yaw_rate_noise", "lateral_speed_noise",
                                         "use_yaw_rate", "non_holonomic", "min_fix", "velocity_noise", "features", "driver"}));
  const std::optional<SensorModality> inferred = infer_modality(name);
  if (node["modality"].present()) {
    Result<std::string> text = node["modality"].as_string();
    if (!text) return text.error();
    const std::optional<SensorModality> modality = sensor_modality_from_string(*text);
    if (!modality) return node["modality"].error(fmt::format("expected imu, lidar, camera, gnss, wheel_odometry or radar, got '{}'", *text));
    sensor.modality = *modality;
  } else if (inferred) {
    sensor.modality = *inferred;
  } else {
    return node.error("cannot tell the sensor's modality from its name; add 'modality: imu|lidar|camera|gnss|wheel_odometry|radar'");
  }
  sensor.topic = "/sensors/" + name;
  if (node["topic"].present()) HANZO_ASSIGN_OR_RETURN(sensor.topic, node["topic"].as_string());
  if (sensor.topic.empty()) return node["topic"].error("expected a topic name, got an empty string");
  if (!node["rate"].present()) return node["rate"].error("missing (expected the sensor's rate in Hz)");
  HANZO_ASSIGN_OR_RETURN(sensor.rate_hz, positive_rate(node["rate"]));
  sensor.body_frame = name + "_link";
  if (node["body_frame"].present()) HANZO_ASSIGN_OR_RETURN(sensor.body_frame, node["body_frame"].as_string());
  if (sensor.body_frame.empty()) return node["body_frame"].error("expected a frame name, got an empty string");
  if (node["type"].present()) HANZO_ASSIGN_OR_RETURN(sensor.type, node["type"].as_string());
  HANZO_ASSIGN_OR_RETURN(sensor.fusion, parse_fusion_options(node, sensor.modality));
  if (const YamlValue features = node["features"]; features.present()) {
    if (sensor.modality != SensorModality::kCamera) return features.error(fmt::format("applies to camera sensors only (this sensor is {})", to_string(sensor.modality)));
    HANZO_ASSIGN_OR_RETURN(sensor.features, parse_features(features));
  }
  if (const YamlValue driver = node["driver"]; driver.present()) HANZO_ASSIGN_OR_RETURN(sensor.driver, parse_driver(driver, sensor.modality));
  return sensor;
}

Result<FusionConfig> parse(const YamlValue& root) {
  HANZO_RETURN_IF_ERROR(root.check_keys({"fusion"}));
  const YamlValue fusion = root["fusion"].as_path_root();
  if (!fusion.present()) return fusion.error("missing (the file must start with a 'fusion:' map)");
  HANZO_RETURN_IF_ERROR(fusion.check_keys({"frontend", "sensors", "mapping", "vision"}));
  FusionConfig config;
  HANZO_ASSIGN_OR_RETURN(config.frontend, parse_frontend(fusion["frontend"]));
  HANZO_ASSIGN_OR_RETURN(config.mapping, parse_mapping(fusion["mapping"]));
  HANZO_ASSIGN_OR_RETURN(config.vision, parse_vision(fusion["vision"]));
  const YamlValue sensors = fusion["sensors"];
  HANZO_RETURN_IF_ERROR(sensors.expect_map());
  std::set<std::string> topics;
  for (const auto& [name, node] : sensors.entries()) {
    if (config.find_sensor(name)) return node.error("duplicate sensor name");
    Result<SensorConfig> sensor = parse_sensor(name, node);
    if (!sensor) return sensor.error();
    if (!topics.insert(sensor->topic).second) {
      return node["topic"].error(fmt::format("topic '{}' is already used by another sensor", sensor->topic));
    }
    config.sensors.push_back(std::move(sensor).value());
  }
  return config;
}

// The options that differ from the defaults, as "      key: value" lines.
std::string fusion_options_yaml(const SensorFusionOptions& o) {
  const SensorFusionOptions d;
  std::string out;
  const auto number = [&out](std::string_view key, double value, double fallback) {
    if (value != fallback) out += fmt::format("      {}: {}\n", key, format_double(value));
  };
  number("timeout", o.timeout_s, d.timeout_s);
  if (o.use_orientation != d.use_orientation) {
    std::vector<std::string> angles;
    for (size_t i = 0; i < 3; ++i) {
      if (o.use_orientation[i]) angles.emplace_back(std::array{"roll", "pitch", "yaw"}[i]);
    }
    out += fmt::format("      use_orientation: [{}]\n", fmt::join(angles, ", "));
  }
  number("orientation_noise", o.orientation_noise, d.orientation_noise);
  number("speed_noise", o.speed_noise, d.speed_noise);
  number("yaw_rate_noise", o.yaw_rate_noise, d.yaw_rate_noise);
  number("lateral_speed_noise", o.lateral_speed_noise, d.lateral_speed_noise);
  if (o.use_yaw_rate != d.use_yaw_rate) out += fmt::format("      use_yaw_rate: {}\n", o.use_yaw_rate);
  if (o.non_holonomic != d.non_holonomic) out += fmt::format("      non_holonomic: {}\n", o.non_holonomic);
  if (o.min_fix != d.min_fix) out += fmt::format("      min_fix: {}\n", msgs::to_string(o.min_fix));
  number("velocity_noise", o.velocity_noise, d.velocity_noise);
  return out;
}

// The mapping block with the keys that differ from the defaults ("" when none do).
std::string mapping_yaml(const MappingConfig& m) {
  const MappingConfig d;
  std::string out;
  const auto flag = [&out](std::string_view key, bool value, bool fallback) {
    if (value != fallback) out += fmt::format("    {}: {}\n", key, value);
  };
  const auto number = [&out](std::string_view key, double value, double fallback) {
    if (value != fallback) out += fmt::format("    {}: {}\n", key, format_double(value));
  };
  flag("enabled", m.enabled, d.enabled);
  number("lidar_voxel", m.lidar_voxel, d.lidar_voxel);
  number("lidar_source_voxel", m.lidar_source_voxel, d.lidar_source_voxel);
  number("lidar_max_range", m.lidar_max_range, d.lidar_max_range);
  number("map_voxel", m.map_voxel, d.map_voxel);
  number("occupancy_resolution", m.occupancy_resolution, d.occupancy_resolution);
  number("keyframe_distance", m.keyframe_distance, d.keyframe_distance);
  number("keyframe_angle", m.keyframe_angle, d.keyframe_angle);
  flag("remove_moving_points", m.remove_moving_points, d.remove_moving_points);
  flag("loop_closure", m.loop_closure, d.loop_closure);
  number("loop_min_travel", m.loop_min_travel, d.loop_min_travel);
  number("loop_search_radius", m.loop_search_radius, d.loop_search_radius);
  number("loop_max_rmse", m.loop_max_rmse, d.loop_max_rmse);
  flag("gnss_factors", m.gnss_factors, d.gnss_factors);
  number("gnss_error_correlation", m.gnss_error_correlation, d.gnss_error_correlation);
  flag("velocity_factors", m.velocity_factors, d.velocity_factors);
  flag("follow_graph", m.follow_graph, d.follow_graph);
  if (m.visual_inertial_window != d.visual_inertial_window) out += fmt::format("    visual_inertial_window: {}\n", m.visual_inertial_window);
  const SplatMappingConfig& splats = m.splats;
  const SplatMappingConfig splat_defaults;
  if (splats.enabled != splat_defaults.enabled || splats.image_width != splat_defaults.image_width || splats.steps_per_view != splat_defaults.steps_per_view ||
      splats.cpu_share != splat_defaults.cpu_share || splats.max_gaussians != splat_defaults.max_gaussians) {
    out += fmt::format("    splats: {{enabled: {}, image_width: {}, steps_per_view: {}, cpu_share: {}, max_gaussians: {}}}\n", splats.enabled, splats.image_width,
                       splats.steps_per_view, format_double(splats.cpu_share), splats.max_gaussians);
  }
  return out.empty() ? out : "  mapping:\n" + out;
}

// `features: TYPE` or, with a model path, `features: {type: TYPE, model: PATH}`.
std::string features_yaml(const FeatureSelection& features) {
  if (features.model.empty()) return std::string(features.type);
  return fmt::format("{{type: {}, model: {}}}", features.type, yaml::scalar(features.model));
}

// The vision block with the keys that differ from the defaults ("" when none do).
std::string vision_yaml(const VisionConfig& v) {
  const VisionConfig d;
  std::string out;
  if (!(v.features == d.features)) out += fmt::format("    features: {}\n", features_yaml(v.features));
  if (v.matcher != d.matcher) out += fmt::format("    matcher: {}\n", to_string(v.matcher));
  if (v.place_recognition) out += fmt::format("    place_recognition: {}\n", to_string(*v.place_recognition));
  if (!v.place_model.empty()) out += fmt::format("    place_model: {}\n", yaml::scalar(v.place_model));
  if (v.local_mapping_thread != d.local_mapping_thread) out += fmt::format("    local_mapping_thread: {}\n", v.local_mapping_thread);
  if (!(v.dynamic_objects == d.dynamic_objects)) {
    std::vector<std::string> classes;
    for (const std::string& name : v.dynamic_objects.classes) classes.push_back(yaml::scalar(name));
    out += fmt::format("    dynamic_objects: {{classes: [{}], min_score: {}, margin_px: {}, wait_for_detections: {}}}\n", fmt::join(classes, ", "),
                       v.dynamic_objects.min_score, v.dynamic_objects.margin_px, v.dynamic_objects.wait_for_detections);
  }
  if (!(v.detector == d.detector)) {
    out += fmt::format("    detector: {{type: {}, model: {}, score_threshold: {}}}\n", v.detector.type, yaml::scalar(v.detector.model), v.detector.score_threshold);
  }
  return out.empty() ? out : "  vision:\n" + out;
}

}  // namespace

Result<FusionConfig> parse_fusion_config(const std::string& yaml_text, const std::string& source_name) {
  Result<YamlValue> root = YamlValue::load_string(yaml_text, source_name);
  if (!root) return root.error();
  return parse(*root);
}

Result<FusionConfig> load_fusion_config(const std::string& path) {
  Result<YamlValue> root = YamlValue::load_file(path);
  if (!root) return root.error();
  return parse(*root);
}

std::string to_yaml(const FusionConfig& config) {
  const CovarianceConfig& c = config.frontend.covariance;
  std::string out = "fusion:\n  frontend:\n";
  out += fmt::format("    type: {}  # ekf | ukf | particle | msckf\n", to_string(config.frontend.type));
  out += fmt::format("    predict_rate: {}  # Hz, IMU propagation rate\n", format_double(config.frontend.predict_rate_hz));
  out += "    covariance:\n";
  out += fmt::format("      initial_position: {}  # meters, diagonal\n", yaml::flow_sequence(c.initial_position));
  out += fmt::format("      initial_orientation: {}  # radians, diagonal\n", yaml::flow_sequence(c.initial_orientation));
  out += fmt::format("      initial_velocity: {}  # m/s, diagonal\n", yaml::flow_sequence(c.initial_velocity));
  out += fmt::format("      process_noise_accel: {}  # m/s^2\n", format_double(c.process_noise_accel));
  out += fmt::format("      process_noise_gyro: {}  # rad/s\n", format_double(c.process_noise_gyro));
  out += fmt::format("      accel_bias_random_walk: {}  # m/s^2/sqrt(Hz)\n", format_double(c.accel_bias_random_walk));
  out += fmt::format("      gyro_bias_random_walk: {}  # rad/s/sqrt(Hz)\n", format_double(c.gyro_bias_random_walk));
  const FrontendConfig& f = config.frontend;
  const FrontendConfig defaults;
  if (f.gate_probability != defaults.gate_probability) out += fmt::format("    gate_probability: {}\n", format_double(f.gate_probability));
  if (f.lag_window_s != defaults.lag_window_s) out += fmt::format("    lag_window: {}  # s\n", format_double(f.lag_window_s));
  if (f.gate_recovery_s != defaults.gate_recovery_s) out += fmt::format("    gate_recovery: {}  # s\n", format_double(f.gate_recovery_s));
  if (f.max_future_s != defaults.max_future_s) out += fmt::format("    max_future: {}  # s\n", format_double(f.max_future_s));
  if (f.static_alignment_s != defaults.static_alignment_s) {
    out += fmt::format("    static_alignment: {}  # s\n", format_double(f.static_alignment_s));
  }
  if (f.keyframe_interval_s) out += fmt::format("    keyframe_interval: {}  # s\n", format_double(*f.keyframe_interval_s));
  if (f.initial_yaw) out += fmt::format("    initial_yaw: {}  # rad, ENU\n", format_double(*f.initial_yaw));
  if (f.planar) out += "    planar: true\n";
  if (!f.zero_velocity_updates) out += "    zero_velocity_updates: false\n";
  if (f.ukf.alpha != defaults.ukf.alpha || f.ukf.beta != defaults.ukf.beta || f.ukf.kappa != defaults.ukf.kappa) {
    out += fmt::format("    ukf: {{alpha: {}, beta: {}, kappa: {}}}\n", format_double(f.ukf.alpha), format_double(f.ukf.beta),
                       format_double(f.ukf.kappa));
  }
  const ParticleFilterSettings& pf = f.particle_filter;
  if (pf.particles != defaults.particle_filter.particles || pf.resample_threshold != defaults.particle_filter.resample_threshold ||
      pf.seed != defaults.particle_filter.seed) {
    out += fmt::format("    particle_filter: {{particles: {}, resample_threshold: {}, seed: {}}}\n", pf.particles,
                       format_double(pf.resample_threshold), pf.seed);
  }
  const MotionModelSettings& motion = f.motion_model;
  if (motion.acceleration_noise != defaults.motion_model.acceleration_noise ||
      motion.angular_acceleration_noise != defaults.motion_model.angular_acceleration_noise) {
    out += fmt::format("    motion_model: {{acceleration_noise: {}, angular_acceleration_noise: {}}}\n", format_double(motion.acceleration_noise),
                       format_double(motion.angular_acceleration_noise));
  }
  if (f.datum) {
    out += fmt::format("    datum: {{latitude: {}, longitude: {}, altitude: {}}}\n", format_double(f.datum->latitude_deg),
                       format_double(f.datum->longitude_deg), format_double(f.datum->altitude_m));
  }
  out += mapping_yaml(config.mapping);
  out += vision_yaml(config.vision);
  out += config.sensors.empty() ? "  sensors: {}\n" : "  sensors:\n";
  for (const SensorConfig& sensor : config.sensors) {
    out += fmt::format("    {}:\n", yaml::scalar(sensor.name));
    if (infer_modality(sensor.name) != sensor.modality) out += fmt::format("      modality: {}\n", to_string(sensor.modality));
    out += fmt::format("      topic: {}\n", yaml::scalar(sensor.topic));
    out += fmt::format("      rate: {}  # Hz\n", format_double(sensor.rate_hz));
    out += fmt::format("      body_frame: {}\n", yaml::scalar(sensor.body_frame));
    if (!sensor.type.empty()) out += fmt::format("      type: {}\n", yaml::scalar(sensor.type));
    out += fusion_options_yaml(sensor.fusion);
    if (sensor.features) out += fmt::format("      features: {}\n", features_yaml(*sensor.features));
  }
  return out;
}

Status save_fusion_config(const FusionConfig& config, const std::string& path) {
  if (Status status = validate(config); !status) return status;
  return yaml::write_file_atomically(path, to_yaml(config));
}

}  // namespace hanzo::fusion::config
