// The scenario YAML loader (layout in scenario.hpp and docs/simulator.md).

#include <cmath>
#include <limits>
#include <numbers>

#include <fmt/format.h>

#include "hanzo/fusion/core/files.hpp"
#include "hanzo/fusion/core/yaml_value.hpp"
#include "hanzo/fusion/sim/city_generator.hpp"
#include "hanzo/fusion/sim/scenario.hpp"

namespace hanzo::fusion::sim {
namespace {

constexpr double kDegree = std::numbers::pi / 180.0;

// ---- scalar helpers: absent -> fallback; present -> checked -----------------------------------

Result<double> number_or(const YamlValue& value, double fallback) {
  if (!value.present()) return fallback;
  return value.as_double();
}

using yaml::non_negative_or;
using yaml::positive_or;

Result<double> probability_or(const YamlValue& value, double fallback) {
  double number = 0.0;
  HANZO_ASSIGN_OR_RETURN(number, number_or(value, fallback));
  if (!(number >= 0.0 && number <= 1.0)) return value.error(fmt::format("expected a probability in [0, 1], got {}", number));
  return number;
}

// A whole number in [minimum, maximum], or fallback when absent: counts, sizes and seeds
// (640.5 pixels is an error, not 640).
template <typename Integer>
Result<Integer> count_or(const YamlValue& value, Integer fallback, int64_t minimum,
                         int64_t maximum = std::numeric_limits<int32_t>::max()) {
  if (!value.present()) return fallback;
  int64_t number = 0;
  HANZO_ASSIGN_OR_RETURN(number, value.as_int64());
  if (number < minimum || number > maximum) {
    return value.error(fmt::format("expected a whole number in {}..{}, got {}", minimum, maximum, number));
  }
  return static_cast<Integer>(number);
}

template <int N>
Result<Eigen::Matrix<double, N, 1>> vector_or(const YamlValue& value, const Eigen::Matrix<double, N, 1>& fallback,
                                              std::string_view description) {
  if (!value.present()) return fallback;
  std::vector<double> numbers;
  HANZO_ASSIGN_OR_RETURN(numbers, value.as_doubles(N, description));
  return Eigen::Matrix<double, N, 1>(numbers.data());
}

Result<Eigen::Vector3f> color_or(const YamlValue& value, const Eigen::Vector3f& fallback) {
  Eigen::Vector3d color = Eigen::Vector3d::Zero();
  HANZO_ASSIGN_OR_RETURN(color, vector_or<3>(value, fallback.cast<double>(), "(r, g, b)"));
  if ((color.array() < 0.0).any() || (color.array() > 1.0).any()) return value.error("colour components must be in [0, 1]");
  return Eigen::Vector3f(color.cast<float>());
}

Result<Timestamp> time_after_start(const YamlValue& value, Timestamp start) {
  double seconds = 0.0;
  HANZO_ASSIGN_OR_RETURN(seconds, value.as_double());
  if (seconds < 0.0) return value.error(fmt::format("expected seconds after the start (>= 0), got {}", seconds));
  return start + Duration::from_seconds(seconds);
}

Result<std::vector<Eigen::Vector3d>> points_3d(const YamlValue& value, bool allow_2d) {
  if (!value.is_sequence()) return value.error("expected a list of points");
  std::vector<Eigen::Vector3d> points;
  for (const YamlValue& item : value.elements()) {
    std::vector<double> numbers;
    HANZO_ASSIGN_OR_RETURN(numbers, item.as_doubles());
    if (numbers.size() == 3 || (allow_2d && numbers.size() == 2)) {
      points.emplace_back(numbers[0], numbers[1], numbers.size() == 3 ? numbers[2] : 0.0);
    } else {
      return item.error(fmt::format("expected {} numbers, got {}", allow_2d ? "2 (x, y) or 3 (x, y, z)" : "3 (x, y, z)", numbers.size()));
    }
  }
  return points;
}

// ---- world -------------------------------------------------------------------------------------

Result<Texture> parse_texture(const YamlValue& value, Texture texture) {
  if (!value.present()) return texture;
  HANZO_RETURN_IF_ERROR(value.check_keys({"type", "color_a", "color_b", "scale", "seed"}));
  if (value["type"].present()) {
    std::string name;
    HANZO_ASSIGN_OR_RETURN(name, value["type"].as_string());
    const std::optional<TextureType> type = texture_type_from_string(name);
    if (!type) return value["type"].error(fmt::format("unknown texture '{}' (expected uniform, checker, noise or poster)", name));
    texture.type = *type;
  }
  HANZO_ASSIGN_OR_RETURN(texture.color_a, color_or(value["color_a"], texture.color_a));
  HANZO_ASSIGN_OR_RETURN(texture.color_b, color_or(value["color_b"], texture.color_b));
  HANZO_ASSIGN_OR_RETURN(texture.scale, positive_or(value["scale"], texture.scale));
  HANZO_ASSIGN_OR_RETURN(texture.seed, count_or(value["seed"], texture.seed, 0, std::numeric_limits<uint32_t>::max()));
  return texture;
}

// The material keys every object accepts.
Status parse_material(const YamlValue& value, Material* material) {
  HANZO_ASSIGN_OR_RETURN(material->texture, parse_texture(value["texture"], material->texture));
  HANZO_ASSIGN_OR_RETURN(material->reflectivity, probability_or(value["reflectivity"], material->reflectivity));
  HANZO_ASSIGN_OR_RETURN(material->radar_cross_section, number_or(value["radar_cross_section"], material->radar_cross_section));
  return ok_status();
}

// Objects without a texture get a noise texture with their own pattern.
Material default_material(uint32_t index) {
  Material material;
  material.texture.type = TextureType::kNoise;
  material.texture.seed = index;
  material.radar_cross_section = 10.0;
  return material;
}

// An object's segmentation / detection class (`class:`), kept as it was when absent.
Status parse_class(const YamlValue& item, std::string* class_name) {
  if (!item["class"].present()) return ok_status();
  HANZO_ASSIGN_OR_RETURN(*class_name, item["class"].as_string());
  if (class_name->empty()) return item["class"].error("a class name must not be empty");
  return ok_status();
}

Status parse_world(const YamlValue& value, Timestamp start, WorldDescription* world) {
  HANZO_RETURN_IF_ERROR(value.check_keys({"ground", "boxes", "cylinders", "walls", "people", "vehicles", "city"}));
  const YamlValue ground = value["ground"];
  world->ground.texture.type = TextureType::kNoise;
  world->ground.texture.scale = 1.0;
  world->ground.reflectivity = 0.3;
  if (ground.present()) {
    HANZO_RETURN_IF_ERROR(ground.check_keys({"enabled", "height", "class", "texture", "reflectivity", "radar_cross_section"}));
    HANZO_RETURN_IF_ERROR(parse_class(ground, &world->ground_class));
    if (ground["enabled"].present()) HANZO_ASSIGN_OR_RETURN(world->has_ground, ground["enabled"].as_bool());
    HANZO_ASSIGN_OR_RETURN(world->ground_height, number_or(ground["height"], 0.0));
    HANZO_RETURN_IF_ERROR(parse_material(ground, &world->ground));
  }
  uint32_t object_index = 1;
  for (const YamlValue& item : value["boxes"].elements()) {
    HANZO_RETURN_IF_ERROR(item.check_keys({"center", "size", "yaw_deg", "class", "texture", "reflectivity", "radar_cross_section"}));
    Box box;
    HANZO_RETURN_IF_ERROR(parse_class(item, &box.class_name));
    box.material = default_material(object_index++);
    HANZO_ASSIGN_OR_RETURN(box.center, vector_or<3>(item["center"], Eigen::Vector3d::Zero(), "(x, y, z)"));
    Eigen::Vector3d size = Eigen::Vector3d::Ones();
    HANZO_ASSIGN_OR_RETURN(size, vector_or<3>(item["size"], size, "(x, y, z)"));
    if ((size.array() <= 0.0).any()) return item["size"].error("sizes must be > 0");
    box.half_size = size / 2.0;
    double yaw = 0.0;
    HANZO_ASSIGN_OR_RETURN(yaw, number_or(item["yaw_deg"], 0.0));
    box.yaw = yaw * kDegree;
    HANZO_RETURN_IF_ERROR(parse_material(item, &box.material));
    world->boxes.push_back(box);
  }
  for (const YamlValue& item : value["walls"].elements()) {
    HANZO_RETURN_IF_ERROR(item.check_keys({"from", "to", "height", "thickness", "class", "texture", "reflectivity", "radar_cross_section"}));
    Eigen::Vector2d from = Eigen::Vector2d::Zero(), to = Eigen::Vector2d::Zero();
    HANZO_ASSIGN_OR_RETURN(from, vector_or<2>(item["from"], from, "(x, y)"));
    HANZO_ASSIGN_OR_RETURN(to, vector_or<2>(item["to"], to, "(x, y)"));
    if ((to - from).norm() < 1e-6) return item["to"].error("a wall needs two different end points");
    double height = 3.0, thickness = 0.2;
    HANZO_ASSIGN_OR_RETURN(height, positive_or(item["height"], height));
    HANZO_ASSIGN_OR_RETURN(thickness, positive_or(item["thickness"], thickness));
    Box wall;
    wall.class_name = "wall";
    HANZO_RETURN_IF_ERROR(parse_class(item, &wall.class_name));
    wall.material = default_material(object_index++);
    const Eigen::Vector2d middle = 0.5 * (from + to);
    wall.center = {middle.x(), middle.y(), world->ground_height + height / 2.0};
    wall.half_size = {0.5 * (to - from).norm(), thickness / 2.0, height / 2.0};
    wall.yaw = std::atan2(to.y() - from.y(), to.x() - from.x());
    HANZO_RETURN_IF_ERROR(parse_material(item, &wall.material));
    world->boxes.push_back(wall);
  }
  for (const YamlValue& item : value["cylinders"].elements()) {
    HANZO_RETURN_IF_ERROR(item.check_keys({"base", "radius", "height", "class", "texture", "reflectivity", "radar_cross_section"}));
    Cylinder cylinder;
    HANZO_RETURN_IF_ERROR(parse_class(item, &cylinder.class_name));
    cylinder.material = default_material(object_index++);
    HANZO_ASSIGN_OR_RETURN(cylinder.base_center, vector_or<3>(item["base"], Eigen::Vector3d::Zero(), "(x, y, z)"));
    HANZO_ASSIGN_OR_RETURN(cylinder.radius, positive_or(item["radius"], 0.2));
    HANZO_ASSIGN_OR_RETURN(cylinder.height, positive_or(item["height"], 3.0));
    HANZO_RETURN_IF_ERROR(parse_material(item, &cylinder.material));
    world->cylinders.push_back(cylinder);
  }
  // People and vehicles: boxes moving along a path; they differ only in their defaults.
  struct MoverDefaults {
    const char* key;
    double speed;
    Eigen::Vector3d size;
    const char* class_name;
    double radar_cross_section;  // dBsm: a person about 1 m^2, a car as the parked ones
  };
  for (const MoverDefaults& kind : {MoverDefaults{"people", 1.2, {0.5, 0.4, 1.75}, "person", 0.0},
                                    MoverDefaults{"vehicles", 8.0, {4.5, 1.8, 1.5}, "car", 15.0}}) {
    for (const YamlValue& item : value[kind.key].elements()) {
      HANZO_RETURN_IF_ERROR(item.check_keys({"path", "speed", "start", "size", "class", "texture", "reflectivity", "radar_cross_section"}));
      MovingBox mover;
      mover.class_name = kind.class_name;
      mover.box.material = default_material(object_index++);
      mover.box.material.radar_cross_section = kind.radar_cross_section;
      std::vector<Eigen::Vector3d> path;
      HANZO_ASSIGN_OR_RETURN(path, points_3d(item["path"], true));
      if (path.size() < 2) return item["path"].error("a path needs at least 2 points");
      for (const Eigen::Vector3d& point : path) mover.path.push_back(point.head<2>());
      HANZO_ASSIGN_OR_RETURN(mover.speed, positive_or(item["speed"], kind.speed));
      mover.start_time = start;
      if (item["start"].present()) HANZO_ASSIGN_OR_RETURN(mover.start_time, time_after_start(item["start"], start));
      Eigen::Vector3d size = kind.size;
      HANZO_ASSIGN_OR_RETURN(size, vector_or<3>(item["size"], size, "(x, y, z)"));
      if ((size.array() <= 0.0).any()) return item["size"].error("sizes must be > 0");
      mover.box.half_size = size / 2.0;
      HANZO_RETURN_IF_ERROR(parse_material(item, &mover.box.material));
      HANZO_RETURN_IF_ERROR(parse_class(item, &mover.class_name));
      world->moving_boxes.push_back(mover);
    }
  }
  const YamlValue city = value["city"];
  if (city.present()) {
    HANZO_RETURN_IF_ERROR(city.check_keys({"origin", "blocks", "block_size", "street_width", "building_height", "pole_spacing",
                                           "parked_cars", "seed"}));
    CityConfig config;
    HANZO_ASSIGN_OR_RETURN(config.origin, vector_or<2>(city["origin"], config.origin, "(x, y)"));
    Eigen::Vector2d blocks(config.blocks_x, config.blocks_y);
    HANZO_ASSIGN_OR_RETURN(blocks, vector_or<2>(city["blocks"], blocks, "(x, y)"));
    if (blocks.x() < 1 || blocks.y() < 1 || blocks.x() > 50 || blocks.y() > 50) return city["blocks"].error("expected 1..50 blocks per direction");
    config.blocks_x = static_cast<int>(blocks.x());
    config.blocks_y = static_cast<int>(blocks.y());
    HANZO_ASSIGN_OR_RETURN(config.block_size, positive_or(city["block_size"], config.block_size));
    HANZO_ASSIGN_OR_RETURN(config.street_width, positive_or(city["street_width"], config.street_width));
    HANZO_ASSIGN_OR_RETURN(config.building_height, vector_or<2>(city["building_height"], config.building_height, "(min, max)"));
    HANZO_ASSIGN_OR_RETURN(config.pole_spacing, non_negative_or(city["pole_spacing"], config.pole_spacing));
    HANZO_ASSIGN_OR_RETURN(config.parked_car_probability, probability_or(city["parked_cars"], config.parked_car_probability));
    HANZO_ASSIGN_OR_RETURN(config.seed, count_or(city["seed"], config.seed, 0, std::numeric_limits<uint32_t>::max()));
    add_city(config, world);
  }
  return ok_status();
}

// ---- trajectory --------------------------------------------------------------------------------

Status parse_ground_path(const YamlValue& value, GroundPathConfig* path) {
  HANZO_ASSIGN_OR_RETURN(path->waypoints, points_3d(value["waypoints"], true));
  if (value["closed"].present()) HANZO_ASSIGN_OR_RETURN(path->closed, value["closed"].as_bool());
  HANZO_ASSIGN_OR_RETURN(path->laps, count_or(value["laps"], path->laps, 1));
  HANZO_ASSIGN_OR_RETURN(path->corner_radius, positive_or(value["corner_radius"], path->corner_radius));
  HANZO_ASSIGN_OR_RETURN(path->max_speed, positive_or(value["max_speed"], path->max_speed));
  HANZO_ASSIGN_OR_RETURN(path->max_acceleration, positive_or(value["max_acceleration"], path->max_acceleration));
  HANZO_ASSIGN_OR_RETURN(path->max_lateral_acceleration, positive_or(value["max_lateral_acceleration"], path->max_lateral_acceleration));
  HANZO_ASSIGN_OR_RETURN(path->still_start, non_negative_or(value["still_start"], path->still_start));
  HANZO_ASSIGN_OR_RETURN(path->still_end, non_negative_or(value["still_end"], path->still_end));
  HANZO_ASSIGN_OR_RETURN(path->knot_spacing, positive_or(value["knot_spacing"], path->knot_spacing));
  return ok_status();
}

Status parse_trajectory(const YamlValue& value, Scenario* scenario) {
  std::string type;
  HANZO_ASSIGN_OR_RETURN(type, value["type"].as_string());
  if (type == "ground_vehicle") {
    scenario->trajectory_type = TrajectoryType::kGroundVehicle;
    HANZO_RETURN_IF_ERROR(value.check_keys({"type", "waypoints", "closed", "laps", "corner_radius", "max_speed", "max_acceleration",
                                            "max_lateral_acceleration", "still_start", "still_end", "knot_spacing"}));
    return parse_ground_path(value, &scenario->ground_path);
  }
  if (type == "handheld") {
    scenario->trajectory_type = TrajectoryType::kHandheld;
    HANZO_RETURN_IF_ERROR(value.check_keys({"type", "waypoints", "closed", "laps", "corner_radius", "max_speed", "max_acceleration",
                                            "max_lateral_acceleration", "still_start", "still_end", "knot_spacing", "bob_amplitude",
                                            "step_frequency", "look_yaw_amplitude", "look_pitch_amplitude", "look_period"}));
    HandheldTrajectoryConfig& handheld = scenario->handheld;
    handheld.walk.max_speed = 1.2;
    handheld.walk.corner_radius = 1.0;
    HANZO_RETURN_IF_ERROR(parse_ground_path(value, &handheld.walk));
    HANZO_ASSIGN_OR_RETURN(handheld.bob_amplitude, non_negative_or(value["bob_amplitude"], handheld.bob_amplitude));
    HANZO_ASSIGN_OR_RETURN(handheld.step_frequency, non_negative_or(value["step_frequency"], handheld.step_frequency));
    HANZO_ASSIGN_OR_RETURN(handheld.look_yaw_amplitude, non_negative_or(value["look_yaw_amplitude"], handheld.look_yaw_amplitude));
    HANZO_ASSIGN_OR_RETURN(handheld.look_pitch_amplitude, non_negative_or(value["look_pitch_amplitude"], handheld.look_pitch_amplitude));
    HANZO_ASSIGN_OR_RETURN(handheld.look_period, positive_or(value["look_period"], handheld.look_period));
    return ok_status();
  }
  if (type == "drone") {
    scenario->trajectory_type = TrajectoryType::kDrone;
    HANZO_RETURN_IF_ERROR(value.check_keys({"type", "center", "size", "period", "duration", "still_start", "ramp_time",
                                            "yaw_amplitude", "yaw_period", "knot_spacing"}));
    DroneTrajectoryConfig& drone = scenario->drone;
    HANZO_ASSIGN_OR_RETURN(drone.center, vector_or<3>(value["center"], drone.center, "(x, y, z)"));
    HANZO_ASSIGN_OR_RETURN(drone.size, vector_or<3>(value["size"], drone.size, "(x, y, z)"));
    HANZO_ASSIGN_OR_RETURN(drone.period, positive_or(value["period"], drone.period));
    HANZO_ASSIGN_OR_RETURN(drone.duration, positive_or(value["duration"], drone.duration));
    HANZO_ASSIGN_OR_RETURN(drone.still_start, non_negative_or(value["still_start"], drone.still_start));
    HANZO_ASSIGN_OR_RETURN(drone.ramp_time, positive_or(value["ramp_time"], drone.ramp_time));
    HANZO_ASSIGN_OR_RETURN(drone.yaw_amplitude, non_negative_or(value["yaw_amplitude"], drone.yaw_amplitude));
    HANZO_ASSIGN_OR_RETURN(drone.yaw_period, positive_or(value["yaw_period"], drone.yaw_period));
    HANZO_ASSIGN_OR_RETURN(drone.knot_spacing, positive_or(value["knot_spacing"], drone.knot_spacing));
    return ok_status();
  }
  if (type == "stations") {
    scenario->trajectory_type = TrajectoryType::kStations;
    HANZO_RETURN_IF_ERROR(value.check_keys({"type", "stations", "hold", "move", "knot_spacing"}));
    StationsTrajectoryConfig& stations = scenario->stations;
    if (!value["stations"].is_sequence()) return value["stations"].error("expected a list of [x, y, z, roll, pitch, yaw] (m, degrees)");
    for (const YamlValue& item : value["stations"].elements()) {
      std::vector<double> numbers;
      HANZO_ASSIGN_OR_RETURN(numbers, item.as_doubles());
      if (numbers.size() != 6) return item.error(fmt::format("expected 6 numbers (x, y, z, roll, pitch, yaw; m, degrees), got {}", numbers.size()));
      constexpr double kRadiansPerDegree = std::numbers::pi / 180.0;
      stations.stations.push_back({Eigen::Vector3d(numbers[0], numbers[1], numbers[2]),
                                   Eigen::Vector3d(numbers[3], numbers[4], numbers[5]) * kRadiansPerDegree});
    }
    HANZO_ASSIGN_OR_RETURN(stations.hold, positive_or(value["hold"], stations.hold));
    HANZO_ASSIGN_OR_RETURN(stations.move, positive_or(value["move"], stations.move));
    HANZO_ASSIGN_OR_RETURN(stations.knot_spacing, positive_or(value["knot_spacing"], stations.knot_spacing));
    return ok_status();
  }
  return value["type"].error(fmt::format("unknown trajectory type '{}' (expected ground_vehicle, drone, handheld or stations)", type));
}

// ---- sensors -----------------------------------------------------------------------------------

Result<SE3> parse_to_body(const YamlValue& value) {
  if (!value.present()) return SE3();
  HANZO_RETURN_IF_ERROR(value.check_keys({"translation", "rotation"}));
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Vector4d rotation(1.0, 0.0, 0.0, 0.0);
  HANZO_ASSIGN_OR_RETURN(translation, vector_or<3>(value["translation"], translation, "(x, y, z)"));
  HANZO_ASSIGN_OR_RETURN(rotation, vector_or<4>(value["rotation"], rotation, "(w, x, y, z)"));
  if (std::abs(rotation.norm() - 1.0) > 1e-3) return value["rotation"].error(fmt::format("not a unit quaternion (norm {})", rotation.norm()));
  return SE3(SO3::from_wxyz(rotation.normalized()), translation);
}

Result<SensorSimulatorConfig> parse_imu(const YamlValue& value, double rate, const ScenarioSensor& sensor) {
  HANZO_RETURN_IF_ERROR(value.check_keys({"modality", "topic", "rate", "to_body", "process_noise_accel", "process_noise_gyro",
                                          "accel_bias_random_walk", "gyro_bias_random_walk", "initial_accel_bias",
                                          "initial_gyro_bias", "gyro_scale_factor", "gravity"}));
  ImuSimulatorConfig config;
  config.rate_hz = rate;
  config.T_body_imu = sensor.T_body_sensor;
  config.frame_id = sensor.name;
  HANZO_ASSIGN_OR_RETURN(config.process_noise_accel, non_negative_or(value["process_noise_accel"], config.process_noise_accel));
  HANZO_ASSIGN_OR_RETURN(config.process_noise_gyro, non_negative_or(value["process_noise_gyro"], config.process_noise_gyro));
  HANZO_ASSIGN_OR_RETURN(config.accel_bias_random_walk, non_negative_or(value["accel_bias_random_walk"], config.accel_bias_random_walk));
  HANZO_ASSIGN_OR_RETURN(config.gyro_bias_random_walk, non_negative_or(value["gyro_bias_random_walk"], config.gyro_bias_random_walk));
  HANZO_ASSIGN_OR_RETURN(config.initial_accel_bias, vector_or<3>(value["initial_accel_bias"], config.initial_accel_bias, "(x, y, z)"));
  HANZO_ASSIGN_OR_RETURN(config.initial_gyro_bias, vector_or<3>(value["initial_gyro_bias"], config.initial_gyro_bias, "(x, y, z)"));
  HANZO_ASSIGN_OR_RETURN(config.gyro_scale_factor, vector_or<3>(value["gyro_scale_factor"], config.gyro_scale_factor, "(x, y, z)"));
  if ((config.gyro_scale_factor.array() <= 0.0).any()) return value["gyro_scale_factor"].error("scale factors must be > 0");
  HANZO_ASSIGN_OR_RETURN(config.gravity, positive_or(value["gravity"], config.gravity));
  return SensorSimulatorConfig(config);
}

Result<SensorSimulatorConfig> parse_lidar(const YamlValue& value, double rate, const ScenarioSensor& sensor) {
  HANZO_RETURN_IF_ERROR(value.check_keys({"modality", "topic", "rate", "to_body", "model", "range_noise", "max_range", "horizontal_fov_deg"}));
  LidarSimulatorConfig config;
  config.rate_hz = rate;
  config.T_body_lidar = sensor.T_body_sensor;
  config.frame_id = sensor.name;
  std::string model_name = "velodyne_vlp16";
  if (value["model"].present()) HANZO_ASSIGN_OR_RETURN(model_name, value["model"].as_string());
  const std::optional<LidarModel> model = lidar_model_from_string(model_name);
  if (!model) return value["model"].error(fmt::format("unknown LiDAR '{}' (expected velodyne_vlp16, velodyne_hdl64, ouster_os1_64 or planar_laser)", model_name));
  config.pattern = LidarPattern::preset(*model);
  HANZO_ASSIGN_OR_RETURN(config.range_noise, non_negative_or(value["range_noise"], config.range_noise));
  HANZO_ASSIGN_OR_RETURN(config.pattern.max_range, positive_or(value["max_range"], config.pattern.max_range));
  double fov_degrees = 360.0;
  HANZO_ASSIGN_OR_RETURN(fov_degrees, positive_or(value["horizontal_fov_deg"], fov_degrees));
  if (fov_degrees > 360.0) return value["horizontal_fov_deg"].error(fmt::format("{} degrees: at most 360", fov_degrees));
  config.pattern.horizontal_fov = fov_degrees * std::numbers::pi / 180.0;
  return SensorSimulatorConfig(config);
}

Result<SensorSimulatorConfig> parse_camera(const YamlValue& value, double rate, const ScenarioSensor& sensor) {
  HANZO_RETURN_IF_ERROR(value.check_keys({"modality", "topic", "rate", "to_body", "width", "height", "fx", "fy", "cx", "cy",
                                          "distortion_model", "distortion_coeffs", "encoding", "supersampling", "pixel_noise", "lighting",
                                          "depth_range", "depth_noise", "detections", "segmentation", "segmentation_noise"}));
  CameraSimulatorConfig config;
  config.rate_hz = rate;
  config.T_body_camera = sensor.T_body_sensor;
  config.frame_id = sensor.name;
  HANZO_ASSIGN_OR_RETURN(config.intrinsics.width, count_or(value["width"], uint32_t{640}, 1, 16384));
  HANZO_ASSIGN_OR_RETURN(config.intrinsics.height, count_or(value["height"], uint32_t{480}, 1, 16384));
  const double width = config.intrinsics.width, height = config.intrinsics.height;
  HANZO_ASSIGN_OR_RETURN(config.intrinsics.fx, positive_or(value["fx"], width * 0.625));  // 77 deg horizontal field of view
  HANZO_ASSIGN_OR_RETURN(config.intrinsics.fy, positive_or(value["fy"], config.intrinsics.fx));
  HANZO_ASSIGN_OR_RETURN(config.intrinsics.cx, number_or(value["cx"], (width - 1.0) / 2.0));
  HANZO_ASSIGN_OR_RETURN(config.intrinsics.cy, number_or(value["cy"], (height - 1.0) / 2.0));
  if (value["distortion_model"].present()) {
    std::string name;
    HANZO_ASSIGN_OR_RETURN(name, value["distortion_model"].as_string());
    const std::optional<msgs::DistortionType> type = msgs::distortion_type_from_string(name);
    if (!type) return value["distortion_model"].error(fmt::format("unknown distortion '{}' (expected none, radtan or equidistant)", name));
    config.distortion.type = *type;
  }
  if (value["distortion_coeffs"].present()) HANZO_ASSIGN_OR_RETURN(config.distortion.coefficients, value["distortion_coeffs"].as_doubles());
  if (value["encoding"].present()) {
    std::string name;
    HANZO_ASSIGN_OR_RETURN(name, value["encoding"].as_string());
    const std::optional<msgs::ImageEncoding> encoding = msgs::image_encoding_from_string(name);
    if (!encoding) return value["encoding"].error(fmt::format("expected mono8, rgb8, depth16 or depth32f, got '{}'", name));
    if (*encoding == msgs::ImageEncoding::kBgr8) {
      return value["encoding"].error(fmt::format("expected mono8, rgb8, depth16 or depth32f, got '{}'", name));
    }
    config.encoding = *encoding;
  }
  if (value["detections"].present()) {
    std::string name;
    HANZO_ASSIGN_OR_RETURN(name, value["detections"].as_string());
    const std::optional<GroundTruthDetections> detections = ground_truth_detections_from_string(name);
    if (!detections) return value["detections"].error(fmt::format("expected none, boxes or masks, got '{}'", name));
    config.ground_truth_detections = *detections;
  }
  if (value["segmentation"].present()) HANZO_ASSIGN_OR_RETURN(config.ground_truth_segmentation, value["segmentation"].as_bool());
  HANZO_ASSIGN_OR_RETURN(config.segmentation_noise, non_negative_or(value["segmentation_noise"], config.segmentation_noise));
  if (config.segmentation_noise >= 1.0) return value["segmentation_noise"].error("a share of pixels in [0, 1)");
  HANZO_ASSIGN_OR_RETURN(config.supersampling, count_or(value["supersampling"], config.supersampling, 1, 4));
  HANZO_ASSIGN_OR_RETURN(config.pixel_noise, non_negative_or(value["pixel_noise"], config.pixel_noise));
  HANZO_ASSIGN_OR_RETURN(config.depth_range, vector_or<2>(value["depth_range"], config.depth_range, "(min, max) m"));
  HANZO_ASSIGN_OR_RETURN(config.depth_noise, non_negative_or(value["depth_noise"], config.depth_noise));
  if (const YamlValue lighting = value["lighting"]; lighting.present()) {
    HANZO_RETURN_IF_ERROR(lighting.check_keys({"sun_direction", "ambient", "diffuse", "exposure", "shadows", "tint", "snow_cover"}));
    HANZO_ASSIGN_OR_RETURN(config.sun_direction, vector_or<3>(lighting["sun_direction"], config.sun_direction, "(x, y, z) towards the sun"));
    if (!(config.sun_direction.norm() > 0.0)) return lighting["sun_direction"].error("expected a non-zero direction");
    HANZO_ASSIGN_OR_RETURN(config.ambient, non_negative_or(lighting["ambient"], config.ambient));
    HANZO_ASSIGN_OR_RETURN(config.diffuse, non_negative_or(lighting["diffuse"], config.diffuse));
    HANZO_ASSIGN_OR_RETURN(config.exposure, positive_or(lighting["exposure"], config.exposure));
    if (lighting["shadows"].present()) HANZO_ASSIGN_OR_RETURN(config.shadows, lighting["shadows"].as_bool());
    Eigen::Vector3d tint = config.tint.cast<double>();
    HANZO_ASSIGN_OR_RETURN(tint, vector_or<3>(lighting["tint"], tint, "(r, g, b) gains"));
    if ((tint.array() < 0.0).any()) return lighting["tint"].error("gains must be >= 0");
    config.tint = tint.cast<float>();
    HANZO_ASSIGN_OR_RETURN(config.snow_cover, non_negative_or(lighting["snow_cover"], config.snow_cover));
    if (config.snow_cover > 1.0) return lighting["snow_cover"].error(fmt::format("expected a share in [0, 1], got {}", config.snow_cover));
  }
  return SensorSimulatorConfig(config);
}

Result<msgs::GnssFixType> parse_fix_type(const YamlValue& value, msgs::GnssFixType fallback) {
  if (!value.present()) return fallback;
  std::string name;
  HANZO_ASSIGN_OR_RETURN(name, value.as_string());
  if (const std::optional<msgs::GnssFixType> type = msgs::gnss_fix_type_from_string(name)) return *type;
  return value.error(fmt::format("unknown fix type '{}' (expected NO_FIX, FIX_2D, FIX_3D, RTK_FLOAT or RTK_FIXED)", name));
}

Result<SensorSimulatorConfig> parse_gnss(const YamlValue& value, double rate, const ScenarioSensor& sensor, const GeodeticPoint& datum) {
  HANZO_RETURN_IF_ERROR(value.check_keys({"modality", "topic", "rate", "to_body", "fix_type", "noise", "correlation_time", "satellites",
                                          "sky_blockage", "constellation", "elevation_mask_deg"}));
  GnssSimulatorConfig config;
  config.rate_hz = rate;
  config.T_body_gnss = sensor.T_body_sensor;
  config.datum = datum;
  HANZO_ASSIGN_OR_RETURN(config.fix_type, parse_fix_type(value["fix_type"], config.fix_type));
  if (value["noise"].present()) {
    Eigen::Vector2d noise = Eigen::Vector2d::Zero();
    HANZO_ASSIGN_OR_RETURN(noise, vector_or<2>(value["noise"], noise, "(horizontal, vertical)"));
    if ((noise.array() < 0.0).any()) return value["noise"].error("standard deviations must be >= 0");
    config.noise = noise;
  }
  HANZO_ASSIGN_OR_RETURN(config.correlation_time, non_negative_or(value["correlation_time"], config.correlation_time));
  HANZO_ASSIGN_OR_RETURN(config.satellites, count_or(value["satellites"], config.satellites, 0, 200));
  if (value["sky_blockage"].present()) HANZO_ASSIGN_OR_RETURN(config.sky_blockage, value["sky_blockage"].as_bool());
  HANZO_ASSIGN_OR_RETURN(config.constellation, count_or(value["constellation"], config.constellation, 4, 200));
  double mask = config.elevation_mask / kDegree;
  HANZO_ASSIGN_OR_RETURN(mask, non_negative_or(value["elevation_mask_deg"], mask));
  if (mask >= 80.0) return value["elevation_mask_deg"].error(fmt::format("expected a mask below 80 deg, got {}", mask));
  config.elevation_mask = mask * kDegree;
  return SensorSimulatorConfig(config);
}

Result<SensorSimulatorConfig> parse_wheels(const YamlValue& value, double rate, const ScenarioSensor& sensor) {
  HANZO_RETURN_IF_ERROR(value.check_keys({"modality", "topic", "rate", "to_body", "wheel_separation", "wheel_radius", "distance_noise",
                                          "scale_error"}));
  WheelOdometrySimulatorConfig config;
  config.rate_hz = rate;
  config.T_body_wheels = sensor.T_body_sensor;
  config.frame_id = sensor.name;
  HANZO_ASSIGN_OR_RETURN(config.wheel_separation, positive_or(value["wheel_separation"], config.wheel_separation));
  HANZO_ASSIGN_OR_RETURN(config.wheel_radius, non_negative_or(value["wheel_radius"], config.wheel_radius));
  HANZO_ASSIGN_OR_RETURN(config.distance_noise, non_negative_or(value["distance_noise"], config.distance_noise));
  HANZO_ASSIGN_OR_RETURN(config.scale_error, vector_or<2>(value["scale_error"], config.scale_error, "(left, right)"));
  return SensorSimulatorConfig(config);
}

Result<SensorSimulatorConfig> parse_radar(const YamlValue& value, double rate, const ScenarioSensor& sensor) {
  HANZO_RETURN_IF_ERROR(value.check_keys({"modality", "topic", "rate", "to_body", "horizontal_fov_deg", "vertical_fov_deg", "max_range",
                                          "range_noise", "velocity_noise", "clutter_rate"}));
  RadarSimulatorConfig config;
  config.rate_hz = rate;
  config.T_body_radar = sensor.T_body_sensor;
  config.frame_id = sensor.name;
  double horizontal = config.horizontal_fov / kDegree, vertical = config.vertical_fov / kDegree;
  HANZO_ASSIGN_OR_RETURN(horizontal, positive_or(value["horizontal_fov_deg"], horizontal));
  HANZO_ASSIGN_OR_RETURN(vertical, positive_or(value["vertical_fov_deg"], vertical));
  config.horizontal_fov = horizontal * kDegree;
  config.vertical_fov = vertical * kDegree;
  HANZO_ASSIGN_OR_RETURN(config.max_range, positive_or(value["max_range"], config.max_range));
  HANZO_ASSIGN_OR_RETURN(config.range_noise, non_negative_or(value["range_noise"], config.range_noise));
  HANZO_ASSIGN_OR_RETURN(config.velocity_noise, non_negative_or(value["velocity_noise"], config.velocity_noise));
  HANZO_ASSIGN_OR_RETURN(config.clutter_rate, non_negative_or(value["clutter_rate"], config.clutter_rate));
  return SensorSimulatorConfig(config);
}

Result<SensorSimulatorConfig> parse_range(const YamlValue& value, double rate, const ScenarioSensor& sensor) {
  HANZO_RETURN_IF_ERROR(value.check_keys({"modality", "topic", "rate", "to_body", "field_of_view_deg", "min_range", "max_range", "range_noise", "radiation"}));
  RangeSimulatorConfig config;
  config.rate_hz = rate;
  config.T_body_range = sensor.T_body_sensor;
  config.frame_id = sensor.name;
  double field_of_view = config.field_of_view / kDegree;
  HANZO_ASSIGN_OR_RETURN(field_of_view, positive_or(value["field_of_view_deg"], field_of_view));
  if (field_of_view >= 180.0) return value["field_of_view_deg"].error("the cone's full angle must be below 180 degrees");
  config.field_of_view = field_of_view * kDegree;
  HANZO_ASSIGN_OR_RETURN(config.min_range, non_negative_or(value["min_range"], config.min_range));
  HANZO_ASSIGN_OR_RETURN(config.max_range, positive_or(value["max_range"], config.max_range));
  if (config.max_range <= config.min_range) return value["max_range"].error("max_range must exceed min_range");
  HANZO_ASSIGN_OR_RETURN(config.range_noise, non_negative_or(value["range_noise"], config.range_noise));
  if (value["radiation"].present()) {
    std::string radiation;
    HANZO_ASSIGN_OR_RETURN(radiation, value["radiation"].as_string());
    if (radiation != "ultrasound" && radiation != "infrared") return value["radiation"].error("expected ultrasound or infrared");
    config.radiation = radiation == "infrared" ? msgs::RangeRadiation::kInfrared : msgs::RangeRadiation::kUltrasound;
  }
  return SensorSimulatorConfig(config);
}

double default_rate(config::SensorModality modality) {
  switch (modality) {
    case config::SensorModality::kImu: return 200.0;
    case config::SensorModality::kLidar: return 10.0;
    case config::SensorModality::kCamera: return 20.0;
    case config::SensorModality::kGnss: return 5.0;
    case config::SensorModality::kWheelOdometry: return 50.0;
    case config::SensorModality::kRadar: return 20.0;
    case config::SensorModality::kRange: return 20.0;
  }
  return 10.0;
}

Result<ScenarioSensor> parse_sensor(const std::string& name, const YamlValue& value, const Scenario& scenario) {
  HANZO_RETURN_IF_ERROR(value.expect_map());
  ScenarioSensor sensor;
  sensor.name = name;
  std::optional<config::SensorModality> modality = config::infer_modality(name);
  if (value["modality"].present()) {
    std::string modality_name;
    HANZO_ASSIGN_OR_RETURN(modality_name, value["modality"].as_string());
    modality = config::sensor_modality_from_string(modality_name);
    if (!modality) return value["modality"].error(fmt::format("unknown modality '{}'", modality_name));
  }
  if (!modality) return value.error("cannot tell the sensor's modality from its name: add `modality: imu|lidar|camera|gnss|wheel_odometry|radar|range`");
  sensor.modality = *modality;
  sensor.topic = "/sensors/" + name;
  if (value["topic"].present()) HANZO_ASSIGN_OR_RETURN(sensor.topic, value["topic"].as_string());
  if (sensor.topic.empty() || sensor.topic[0] != '/') return value["topic"].error("a topic starts with '/'");
  double rate = 0.0;
  HANZO_ASSIGN_OR_RETURN(rate, positive_or(value["rate"], default_rate(sensor.modality)));
  HANZO_ASSIGN_OR_RETURN(sensor.T_body_sensor, parse_to_body(value["to_body"]));
  Result<SensorSimulatorConfig> simulator = Error{"unknown modality"};
  switch (sensor.modality) {
    case config::SensorModality::kImu: simulator = parse_imu(value, rate, sensor); break;
    case config::SensorModality::kLidar: simulator = parse_lidar(value, rate, sensor); break;
    case config::SensorModality::kCamera: simulator = parse_camera(value, rate, sensor); break;
    case config::SensorModality::kGnss: simulator = parse_gnss(value, rate, sensor, scenario.datum); break;
    case config::SensorModality::kWheelOdometry: simulator = parse_wheels(value, rate, sensor); break;
    case config::SensorModality::kRadar: simulator = parse_radar(value, rate, sensor); break;
    case config::SensorModality::kRange: simulator = parse_range(value, rate, sensor); break;
  }
  if (!simulator) return simulator.error();
  sensor.simulator = std::move(*simulator);
  return sensor;
}

// ---- faults ------------------------------------------------------------------------------------

// The sensors a fault applies to: the named one (which must have the right modality), or every
// sensor of that modality.
Result<std::vector<ScenarioSensor*>> fault_targets(const YamlValue& fault, config::SensorModality modality, Scenario* scenario) {
  std::vector<ScenarioSensor*> targets;
  std::string name;
  if (fault["sensor"].present()) HANZO_ASSIGN_OR_RETURN(name, fault["sensor"].as_string());
  for (ScenarioSensor& sensor : scenario->sensors) {
    if (sensor.modality == modality && (name.empty() || sensor.name == name)) targets.push_back(&sensor);
  }
  if (targets.empty()) {
    return fault.error(name.empty() ? fmt::format("no {} sensor in the scenario for this fault", config::to_string(modality))
                                    : fmt::format("no {} sensor named '{}'", config::to_string(modality), name));
  }
  return targets;
}

Status parse_fault(const YamlValue& fault, Scenario* scenario) {
  std::string type;
  HANZO_ASSIGN_OR_RETURN(type, fault["type"].as_string());
  Timestamp start, end;
  HANZO_ASSIGN_OR_RETURN(start, time_after_start(fault["start"], scenario->start_time));
  HANZO_ASSIGN_OR_RETURN(end, time_after_start(fault["end"], scenario->start_time));
  if (end <= start) return fault["end"].error("a fault must end after it starts");
  std::vector<ScenarioSensor*> targets;
  if (type == "rain" || type == "fog") {
    HANZO_RETURN_IF_ERROR(fault.check_keys({"type", "sensor", "start", "end", "dropout_probability", "phantom_probability",
                                            "phantom_max_range", "visibility_range"}));
    const bool fog = type == "fog";
    LidarWeatherEpisode episode{start, end, fog ? 0.05 : 0.1, fog ? 0.01 : 0.02, 3.0, fog ? 15.0 : 40.0};
    HANZO_ASSIGN_OR_RETURN(episode.dropout_probability, probability_or(fault["dropout_probability"], episode.dropout_probability));
    HANZO_ASSIGN_OR_RETURN(episode.phantom_probability, probability_or(fault["phantom_probability"], episode.phantom_probability));
    HANZO_ASSIGN_OR_RETURN(episode.phantom_max_range, positive_or(fault["phantom_max_range"], episode.phantom_max_range));
    HANZO_ASSIGN_OR_RETURN(episode.visibility_range, positive_or(fault["visibility_range"], episode.visibility_range));
    HANZO_ASSIGN_OR_RETURN(targets, fault_targets(fault, config::SensorModality::kLidar, scenario));
    for (ScenarioSensor* sensor : targets) std::get<LidarSimulatorConfig>(sensor->simulator).weather.push_back(episode);
    return ok_status();
  }
  if (type == "gnss_outage" || type == "gnss_degraded") {
    HANZO_RETURN_IF_ERROR(fault.check_keys({"type", "sensor", "start", "end", "fix_type", "noise_scale", "multipath_rate",
                                            "multipath_magnitude", "multipath_duration", "satellites"}));
    GnssEpisode episode;
    episode.type = type == "gnss_outage" ? GnssEpisodeType::kOutage : GnssEpisodeType::kDegraded;
    episode.start = start;
    episode.end = end;
    HANZO_ASSIGN_OR_RETURN(episode.fix_type, parse_fix_type(fault["fix_type"], episode.fix_type));
    HANZO_ASSIGN_OR_RETURN(episode.noise_scale, positive_or(fault["noise_scale"], episode.noise_scale));
    HANZO_ASSIGN_OR_RETURN(episode.multipath_rate_hz, non_negative_or(fault["multipath_rate"], episode.multipath_rate_hz));
    HANZO_ASSIGN_OR_RETURN(episode.multipath_magnitude, non_negative_or(fault["multipath_magnitude"], episode.multipath_magnitude));
    HANZO_ASSIGN_OR_RETURN(episode.multipath_duration, non_negative_or(fault["multipath_duration"], episode.multipath_duration));
    HANZO_ASSIGN_OR_RETURN(episode.satellites, count_or(fault["satellites"], episode.satellites, 0, 200));
    HANZO_ASSIGN_OR_RETURN(targets, fault_targets(fault, config::SensorModality::kGnss, scenario));
    for (ScenarioSensor* sensor : targets) std::get<GnssSimulatorConfig>(sensor->simulator).episodes.push_back(episode);
    return ok_status();
  }
  if (type == "wheel_slip") {
    HANZO_RETURN_IF_ERROR(fault.check_keys({"type", "sensor", "start", "end", "left_scale", "right_scale"}));
    WheelSlipEpisode slip{start, end, 1.3, 1.0};
    HANZO_ASSIGN_OR_RETURN(slip.left_scale, non_negative_or(fault["left_scale"], slip.left_scale));
    HANZO_ASSIGN_OR_RETURN(slip.right_scale, non_negative_or(fault["right_scale"], slip.right_scale));
    HANZO_ASSIGN_OR_RETURN(targets, fault_targets(fault, config::SensorModality::kWheelOdometry, scenario));
    for (ScenarioSensor* sensor : targets) std::get<WheelOdometrySimulatorConfig>(sensor->simulator).slips.push_back(slip);
    return ok_status();
  }
  if (const std::optional<CameraFaultType> camera_fault = camera_fault_type_from_string(type)) {
    HANZO_RETURN_IF_ERROR(fault.check_keys({"type", "sensor", "start", "end", "brightness", "noise_scale", "center", "radius",
                                            "strength", "exposure_time", "blur_samples"}));
    CameraFaultEpisode episode;
    episode.type = *camera_fault;
    episode.start = start;
    episode.end = end;
    HANZO_ASSIGN_OR_RETURN(episode.brightness, probability_or(fault["brightness"], episode.brightness));
    HANZO_ASSIGN_OR_RETURN(episode.noise_scale, non_negative_or(fault["noise_scale"], episode.noise_scale));
    HANZO_ASSIGN_OR_RETURN(episode.center, vector_or<2>(fault["center"], episode.center, "(u, v) pixels"));
    HANZO_ASSIGN_OR_RETURN(episode.radius, positive_or(fault["radius"], episode.radius));
    HANZO_ASSIGN_OR_RETURN(episode.strength, non_negative_or(fault["strength"], episode.strength));
    HANZO_ASSIGN_OR_RETURN(episode.exposure_time, non_negative_or(fault["exposure_time"], episode.exposure_time));
    HANZO_ASSIGN_OR_RETURN(episode.blur_samples, count_or(fault["blur_samples"], episode.blur_samples, 1, 64));
    HANZO_ASSIGN_OR_RETURN(targets, fault_targets(fault, config::SensorModality::kCamera, scenario));
    for (ScenarioSensor* sensor : targets) std::get<CameraSimulatorConfig>(sensor->simulator).faults.push_back(episode);
    return ok_status();
  }
  return fault["type"].error(fmt::format("unknown fault '{}' (expected rain, fog, gnss_outage, gnss_degraded, wheel_slip, "
                                         "darkness, glare or motion_blur)", type));
}

}  // namespace

Result<Scenario> parse_scenario(const std::string& yaml_text, const std::string& source_name) {
  Result<YamlValue> loaded = YamlValue::load_string(yaml_text, source_name);
  if (!loaded) return loaded.error();
  const YamlValue& document = *loaded;
  HANZO_RETURN_IF_ERROR(document.check_keys({"scenario"}));
  const YamlValue root = document["scenario"].as_path_root();
  if (!root.is_map()) return document.error("expected a top-level `scenario:` map");
  HANZO_RETURN_IF_ERROR(root.check_keys({"name", "seed", "start_time", "datum", "ground_truth_rate", "threads", "duration", "log_start", "world",
                                         "trajectory", "sensors", "faults"}));
  Scenario scenario;
  HANZO_ASSIGN_OR_RETURN(scenario.name, root["name"].as_string());
  HANZO_ASSIGN_OR_RETURN(scenario.seed, count_or(root["seed"], scenario.seed, 0, std::numeric_limits<int64_t>::max()));
  double start_seconds = scenario.start_time.seconds();
  HANZO_ASSIGN_OR_RETURN(start_seconds, positive_or(root["start_time"], start_seconds));
  scenario.start_time = Timestamp::from_seconds(start_seconds);
  const YamlValue datum = root["datum"];
  if (datum.present()) {
    HANZO_RETURN_IF_ERROR(datum.check_keys({"latitude", "longitude", "altitude"}));
    HANZO_ASSIGN_OR_RETURN(scenario.datum.latitude_deg, datum["latitude"].as_double());
    HANZO_ASSIGN_OR_RETURN(scenario.datum.longitude_deg, datum["longitude"].as_double());
    HANZO_ASSIGN_OR_RETURN(scenario.datum.altitude_m, number_or(datum["altitude"], 0.0));
    if (Status valid = validate(scenario.datum); !valid) return datum.error(valid.error().message);
  }
  HANZO_ASSIGN_OR_RETURN(scenario.ground_truth_rate_hz, positive_or(root["ground_truth_rate"], scenario.ground_truth_rate_hz));
  HANZO_ASSIGN_OR_RETURN(scenario.num_threads, count_or(root["threads"], scenario.num_threads, 0, 1024));
  if (root["duration"].present()) HANZO_ASSIGN_OR_RETURN(scenario.duration, positive_or(root["duration"], 0.0));
  HANZO_ASSIGN_OR_RETURN(scenario.log_start, non_negative_or(root["log_start"], 0.0));
  HANZO_RETURN_IF_ERROR(parse_world(root["world"], scenario.start_time, &scenario.world));
  if (!root["trajectory"].present()) return root["trajectory"].error("missing (every scenario needs a trajectory)");
  HANZO_RETURN_IF_ERROR(parse_trajectory(root["trajectory"], &scenario));
  if (!root["sensors"].is_map() || root["sensors"].entries().empty()) return root["sensors"].error("expected a map of at least one sensor");
  for (const auto& [name, value] : root["sensors"].entries()) {
    ScenarioSensor sensor;
    HANZO_ASSIGN_OR_RETURN(sensor, parse_sensor(name, value, scenario));
    scenario.sensors.push_back(std::move(sensor));
  }
  set_seed(scenario, scenario.seed);
  for (const YamlValue& fault : root["faults"].elements()) HANZO_RETURN_IF_ERROR(parse_fault(fault, &scenario));
  if (root["faults"].present() && !root["faults"].is_sequence()) return root["faults"].error("expected a list of faults");
  return scenario;
}

Result<Scenario> load_scenario(const std::string& path) {
  std::string text;
  HANZO_ASSIGN_OR_RETURN(text, read_file(path));
  return parse_scenario(text, path);
}

}  // namespace hanzo::fusion::sim
