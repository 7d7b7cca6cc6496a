#include "hanzo/fusion/config/fusion_config.hpp"

#include <cmath>
#include <filesystem>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

namespace hanzo::fusion::config {
namespace {

using ::testing::HasSubstr;

std::string error_of(const std::string& yaml) {
  const Result<FusionConfig> config = parse_fusion_config(yaml, "fusion.yaml");
  return config.ok() ? std::string("(loaded)") : config.error().message;
}

TEST(FusionConfig, SpecExampleLoadsUnchanged) {
  const Result<FusionConfig> loaded = load_fusion_config("examples/fusion.yaml");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  const FusionConfig& config = *loaded;
  EXPECT_EQ(config.frontend.type, FrontendType::kEkf);
  EXPECT_EQ(config.frontend.predict_rate_hz, 200.0);
  EXPECT_EQ(config.frontend.covariance.initial_orientation, Eigen::Vector3d(0.01, 0.01, 0.01));
  EXPECT_EQ(config.frontend.covariance.gyro_bias_random_walk, 0.0001);
  ASSERT_EQ(config.sensors.size(), 6U);
  EXPECT_EQ(config.sensors[0].name, "imu");
  EXPECT_EQ(config.sensors[0].modality, SensorModality::kImu);
  const SensorConfig* lidar = config.find_sensor("lidar");
  ASSERT_NE(lidar, nullptr);
  EXPECT_EQ(lidar->topic, "/sensors/lidar");
  EXPECT_EQ(lidar->rate_hz, 10.0);
  EXPECT_EQ(lidar->body_frame, "lidar_link");
  EXPECT_EQ(lidar->type, "velodyne_vlp16");
  EXPECT_EQ(config.find_sensor("camera_right")->modality, SensorModality::kCamera);
  EXPECT_EQ(config.find_sensor("camera_right")->type, "stereo_right");
  EXPECT_EQ(config.find_sensor("wheels")->modality, SensorModality::kWheelOdometry);
  EXPECT_EQ(config.find_sensor("gnss")->rate_hz, 5.0);
  EXPECT_TRUE(validate(config).ok());
}

TEST(FusionConfig, DefaultsApplyWhereTheFileIsSilent) {
  const Result<FusionConfig> loaded = parse_fusion_config("fusion:\n  sensors:\n    imu:\n      rate: 100\n", "fusion.yaml");
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(loaded->frontend.type, FrontendType::kEkf);
  EXPECT_EQ(loaded->frontend.predict_rate_hz, 200.0);
  EXPECT_EQ(loaded->frontend.covariance.process_noise_accel, 0.1);
  EXPECT_EQ(loaded->sensors[0].topic, "/sensors/imu");
  EXPECT_EQ(loaded->sensors[0].body_frame, "imu_link");
  EXPECT_EQ(loaded->sensors[0].type, "");
  EXPECT_EQ(loaded->frontend.keyframe_interval(), kDefaultKeyframeInterval);
}

TEST(FusionConfig, TheMsckfKeyframeIntervalDefaultsToHalfASecondAndRoundTrips) {
  const std::string head = "fusion:\n  frontend:\n    type: msckf\n";
  const std::string sensors = "  sensors:\n    imu:\n      rate: 100\n";
  const FusionConfig silent = parse_fusion_config(head + sensors, "fusion.yaml").value();
  EXPECT_EQ(silent.frontend.keyframe_interval(), kVisualInertialKeyframeInterval);
  const FusionConfig one_second = parse_fusion_config(head + "    keyframe_interval: 1.0\n" + sensors, "fusion.yaml").value();
  EXPECT_EQ(one_second.frontend.keyframe_interval(), 1.0);
  for (const FusionConfig& config : {silent, one_second}) {
    const Result<FusionConfig> reloaded = parse_fusion_config(to_yaml(config), "fusion.yaml");
    ASSERT_TRUE(reloaded.ok()) << reloaded.error().message;
    EXPECT_EQ(reloaded->frontend.keyframe_interval_s, config.frontend.keyframe_interval_s);
  }
  // A configuration built in code gets the same defaults, and they follow the type.
  FrontendConfig in_code;
  EXPECT_EQ(in_code.keyframe_interval(), kDefaultKeyframeInterval);
  in_code.type = FrontendType::kMsckf;
  EXPECT_EQ(in_code.keyframe_interval(), kVisualInertialKeyframeInterval);
  in_code.keyframe_interval_s = 2.0;
  EXPECT_EQ(in_code.keyframe_interval(), 2.0);
}

TEST(FusionConfig, EachRuleGivesItsDocumentedError) {
  EXPECT_EQ(error_of("fusion:\n  frontend:\n    type: kalman\n"),
            "fusion.yaml:3: frontend.type: expected ekf, ukf, particle or msckf, got 'kalman'");
  EXPECT_EQ(error_of("fusion:\n  frontend:\n    predict_rate: -5\n"),
            "fusion.yaml:3: frontend.predict_rate: expected a positive rate in Hz, got -5");
  EXPECT_EQ(error_of("fusion:\n  frontend:\n    covariance:\n      initial_position: [0.1, 0.1]\n"),
            "fusion.yaml:4: frontend.covariance.initial_position: expected 3 numbers (x, y, z), got 2");
  EXPECT_EQ(error_of("fusion:\n  frontend:\n    covariance:\n      process_noise_gyro: -0.01\n"),
            "fusion.yaml:4: frontend.covariance.process_noise_gyro: expected a number >= 0, got -0.01");
  EXPECT_EQ(error_of("fusion:\n  frontend:\n    covariance:\n      process_noise_accel: .nan\n"),
            "fusion.yaml:4: frontend.covariance.process_noise_accel: expected a finite number, got '.nan'");
  EXPECT_EQ(error_of("fusion:\n  frontend:\n    tpye: ekf\n"),
            "fusion.yaml:3: frontend.tpye: unknown key (expected one of: type, predict_rate, covariance, gate_probability, lag_window, "
            "max_future, static_alignment, planar, zero_velocity_updates, datum, ukf, particle_filter, keyframe_interval, "
            "gate_recovery, motion_model, initial_yaw)");
  EXPECT_EQ(error_of("fusion:\n  frontend:\n    motion_model: {acceleration_noise: 0}\n"),
            "fusion.yaml:3: frontend.motion_model.acceleration_noise: expected a positive number, got 0");
  EXPECT_EQ(error_of("fusion:\n  sensors:\n    imu:\n      topic: /imu\n"),
            "fusion.yaml:3: sensors.imu.rate: missing (expected the sensor's rate in Hz)");
  EXPECT_EQ(error_of("fusion:\n  sensors:\n    imu:\n      rate: fast\n"),
            "fusion.yaml:4: sensors.imu.rate: expected a number, got 'fast'");
  EXPECT_EQ(error_of("fusion:\n  sensors:\n    front:\n      rate: 10\n"),
            "fusion.yaml:3: sensors.front: cannot tell the sensor's modality from its name; add 'modality: "
            "imu|lidar|camera|gnss|wheel_odometry|radar'");
  EXPECT_EQ(error_of("fusion:\n  sensors:\n    front:\n      rate: 10\n      modality: sonar\n"),
            "fusion.yaml:5: sensors.front.modality: expected imu, lidar, camera, gnss, wheel_odometry or radar, got 'sonar'");
  EXPECT_EQ(error_of("fusion:\n  sensors:\n    imu:\n      rate: 10\n      topic: /a\n    gnss:\n      rate: 5\n      topic: /a\n"),
            "fusion.yaml:8: sensors.gnss.topic: topic '/a' is already used by another sensor");
  EXPECT_EQ(error_of("fusion:\n  sensors: [imu, gnss]\n"), "fusion.yaml:2: sensors: expected a map of keys, got a list of 2");
  EXPECT_EQ(error_of("frontend:\n  type: ekf\n"), "fusion.yaml:1: frontend: unknown key (expected one of: fusion)");
  EXPECT_EQ(error_of("other: 1\n").substr(0, 14), "fusion.yaml:1:");
  EXPECT_EQ(error_of(""), "fusion.yaml:1: fusion: missing (the file must start with a 'fusion:' map)");
  EXPECT_THAT(error_of("fusion:\n  frontend: [\n"), HasSubstr("YAML syntax error"));
  // A key given twice would silently keep one value: refused with both lines.
  EXPECT_EQ(error_of("fusion:\n  frontend:\n    type: ekf\n    predict_rate: 100\n    type: msckf\n"),
            "fusion.yaml:5: duplicate key 'type' (first at line 3)");
  EXPECT_EQ(error_of("fusion:\n  sensors:\n    imu:\n      rate: 100\n    imu:\n      rate: 200\n"),
            "fusion.yaml:5: duplicate key 'imu' (first at line 3)");
}

TEST(FusionConfig, LoadSaveLoadIsLossless) {
  FusionConfig config = load_fusion_config("examples/fusion.yaml").value();
  config.frontend.type = FrontendType::kUkf;
  config.frontend.covariance.process_noise_accel = 0.123456789012345;
  config.frontend.gate_probability = 0.99;
  config.frontend.lag_window_s = 0.25;
  config.frontend.planar = true;
  config.frontend.keyframe_interval_s = 0.5;
  config.frontend.gate_recovery_s = 0.0;
  config.frontend.ukf = {0.5, 1.0, -2.0};
  config.frontend.particle_filter = {2000, 0.25, 7};
  config.frontend.motion_model = {1.5, 0.25};
  config.frontend.datum = GeodeticPoint{48.1, 11.5, 520.25};
  config.mapping.lidar_source_voxel = 0.25;
  config.mapping.map_voxel = 0.05;
  config.mapping.loop_closure = false;
  config.mapping.keyframe_angle = 0.0;
  config.mapping.visual_inertial_window = 0;
  config.mapping.splats = {.enabled = true, .image_width = 320, .steps_per_view = 4, .cpu_share = 0.25, .max_gaussians = 50000};
  config.sensors.push_back({"front_radar", SensorModality::kRadar, "/radar: front", 13.5, "radar link", "continental_ars408",
                            {.timeout_s = 0.3, .velocity_noise = 0.2}});
  config.sensors.push_back({"tracker", SensorModality::kGnss, "/gps", 1.0 / 3.0, "gps_link", "",
                            {.min_fix = msgs::GnssFixType::kRtkFloat}});
  config.sensors.push_back({"imu2", SensorModality::kImu, "/imu2", 100.0, "imu2_link", "",
                            {.use_orientation = {true, false, true}, .orientation_noise = 0.02}});
  config.sensors.push_back({"wheels2", SensorModality::kWheelOdometry, "/wheels2", 50.0, "base_link", "",
                            {.speed_noise = 0.1, .use_yaw_rate = true, .non_holonomic = false}});
  config.vision.features = {"aliked-n16", "/models/ALIKED weights/aliked-n16.pth"};
  config.vision.matcher = MatcherType::kLearned;
  config.vision.place_recognition = PlaceRecognitionType::kLearned;
  config.vision.place_model = "models/vlad.hzvlad";
  config.vision.local_mapping_thread = true;
  config.sensors.push_back({"camera_front", SensorModality::kCamera, "/camera", 20.0, "camera_link", "", {}, FeatureSelection{"orb", ""}});
  const std::filesystem::path path = std::filesystem::temp_directory_path() / "hanzo_fusion_config_test.yaml";
  ASSERT_TRUE(save_fusion_config(config, path.string()).ok());
  const Result<FusionConfig> loaded = load_fusion_config(path.string());
  ASSERT_TRUE(loaded.ok()) << loaded.error().message;
  EXPECT_EQ(to_yaml(*loaded), to_yaml(config));
  EXPECT_EQ(loaded->frontend.type, FrontendType::kUkf);
  EXPECT_TRUE(loaded->frontend.planar);
  EXPECT_EQ(loaded->find_sensor("tracker")->fusion.min_fix, msgs::GnssFixType::kRtkFloat);
  EXPECT_EQ(loaded->find_sensor("imu2")->fusion.use_orientation, (std::array<bool, 3>{true, false, true}));
  EXPECT_TRUE(loaded->find_sensor("wheels2")->fusion.use_yaw_rate);
  EXPECT_EQ(loaded->frontend.covariance.process_noise_accel, 0.123456789012345);
  EXPECT_EQ(loaded->frontend.motion_model.angular_acceleration_noise, 0.25);
  EXPECT_EQ(loaded->mapping.lidar_source_voxel, 0.25);
  EXPECT_EQ(loaded->mapping.map_voxel, 0.05);
  EXPECT_FALSE(loaded->mapping.loop_closure);
  EXPECT_EQ(loaded->mapping.keyframe_angle, 0.0);
  EXPECT_EQ(loaded->mapping.visual_inertial_window, 0);
  EXPECT_TRUE(loaded->mapping.splats.enabled);
  EXPECT_EQ(loaded->mapping.splats.image_width, 320);
  EXPECT_EQ(loaded->mapping.splats.cpu_share, 0.25);
  EXPECT_EQ(loaded->mapping.splats.max_gaussians, 50000);
  EXPECT_EQ(loaded->mapping.occupancy_resolution, MappingConfig{}.occupancy_resolution);
  EXPECT_EQ(loaded->vision.features, (FeatureSelection{"aliked-n16", "/models/ALIKED weights/aliked-n16.pth"}));
  EXPECT_EQ(loaded->vision.matcher, MatcherType::kLearned);
  EXPECT_EQ(loaded->vision.place_recognition, PlaceRecognitionType::kLearned);
  EXPECT_EQ(loaded->vision.place_model, "models/vlad.hzvlad");
  EXPECT_TRUE(loaded->vision.local_mapping_thread);
  EXPECT_EQ(loaded->features_of(*loaded->find_sensor("camera_front")).type, "orb");
  EXPECT_EQ(loaded->features_of(*loaded->find_sensor("imu2")).type, "aliked-n16");
  ASSERT_EQ(loaded->sensors.size(), 11U);
  EXPECT_EQ(loaded->sensors[6].topic, "/radar: front");
  EXPECT_EQ(loaded->sensors[6].modality, SensorModality::kRadar);
  EXPECT_EQ(loaded->sensors[7].modality, SensorModality::kGnss);
  EXPECT_EQ(loaded->sensors[7].rate_hz, 1.0 / 3.0);
  std::filesystem::remove(path);
}

TEST(FusionConfig, MappingBlockIsCheckedKeyByKey) {
  const std::string sensors = "  sensors:\n    imu: {rate: 100}\n";
  EXPECT_THAT(error_of("fusion:\n  mapping:\n    map_voxel: 0\n" + sensors), HasSubstr("fusion.yaml:3: mapping.map_voxel: expected a positive number, got 0"));
  EXPECT_THAT(error_of("fusion:\n  mapping:\n    visual_inertial_window: -3\n" + sensors),
              HasSubstr("fusion.yaml:3: mapping.visual_inertial_window: expected a number of keyframes >= 0, got -3"));
  EXPECT_THAT(error_of("fusion:\n  mapping:\n    keyframe_distance: -1\n" + sensors), HasSubstr("mapping.keyframe_distance"));
  EXPECT_THAT(error_of("fusion:\n  mapping:\n    loop_closure: maybe\n" + sensors), HasSubstr("mapping.loop_closure"));
  EXPECT_THAT(error_of("fusion:\n  mapping:\n    map_voxels: 0.1\n" + sensors), HasSubstr("map_voxels"));
  EXPECT_THAT(error_of("fusion:\n  mapping:\n    splats: {cpu_share: 2}\n" + sensors), HasSubstr("mapping.splats.cpu_share: expected a share of one core in (0, 1], got 2"));
  EXPECT_THAT(error_of("fusion:\n  mapping:\n    splats: {image_width: 8}\n" + sensors), HasSubstr("mapping.splats.image_width: expected an integer >= 16, got 8"));
  EXPECT_TRUE(parse_fusion_config("fusion:\n  mapping:\n    splats: true\n" + sensors, "fusion.yaml").value().mapping.splats.enabled);
  EXPECT_TRUE(parse_fusion_config("fusion:\n  mapping:\n    splats: {steps_per_view: 5}\n" + sensors, "fusion.yaml").value().mapping.splats.enabled);
  FusionConfig config = parse_fusion_config("fusion:\n  mapping: {enabled: false, lidar_voxel: 0.5}\n" + sensors, "fusion.yaml").value();
  EXPECT_FALSE(config.mapping.enabled);
  EXPECT_EQ(config.mapping.lidar_voxel, 0.5);
  config.mapping.loop_max_rmse = std::nan("");
  EXPECT_THAT(validate(config).error().message, HasSubstr("mapping.loop_max_rmse"));
}

TEST(FusionConfig, VisionBlockChoosesFeaturesPerCamera) {
  const std::string sensors = "  sensors:\n    camera: {rate: 10, features: alike-t}\n    camera_rear: {rate: 10}\n";
  FusionConfig config = parse_fusion_config("fusion:\n  vision: {features: {type: aliked-t16, model: weights.pth}, matcher: learned}\n" + sensors,
                                            "fusion.yaml").value();
  EXPECT_EQ(config.features_of(config.sensors[0]), (FeatureSelection{"alike-t", ""}));
  EXPECT_EQ(config.features_of(config.sensors[1]), (FeatureSelection{"aliked-t16", "weights.pth"}));
  EXPECT_EQ(config.vision.matcher, MatcherType::kLearned);
  EXPECT_EQ(parse_fusion_config("fusion:\n" + sensors, "fusion.yaml").value().vision.features.type, "orb");  // the default
  EXPECT_THAT(error_of("fusion:\n  vision:\n    features: superpoint\n" + sensors),
              HasSubstr("fusion.yaml:3: vision.features: expected orb, aliked-t16, aliked-n16, aliked-n16rot, aliked-n32, alike-t, alike-s, alike-n, alike-l, got 'superpoint'"));
  EXPECT_THAT(error_of("fusion:\n  vision: {features: {type: orb, model: x.pth}}\n" + sensors), HasSubstr("ORB takes no model"));
  EXPECT_THAT(error_of("fusion:\n  vision: {matcher: superglue}\n" + sensors), HasSubstr("expected ratio or learned, got 'superglue'"));
  EXPECT_THAT(error_of("fusion:\n  vision: {place_recognition: netvlad}\n" + sensors), HasSubstr("expected bow or learned, got 'netvlad'"));
  EXPECT_THAT(error_of("fusion:\n  vision: {local_mapping_thread: sometimes}\n" + sensors), HasSubstr("local_mapping_thread"));
  EXPECT_FALSE(parse_fusion_config("fusion:\n" + sensors, "fusion.yaml").value().vision.local_mapping_thread);  // the Session's default
  EXPECT_FALSE(config.vision.place_recognition);  // unset: chosen by the features
  EXPECT_EQ(parse_fusion_config("fusion:\n  vision: {place_recognition: learned, place_model: v.hzvlad}\n" + sensors, "fusion.yaml").value().vision.place_recognition,
            PlaceRecognitionType::kLearned);
  EXPECT_THAT(error_of("fusion:\n  sensors:\n    imu: {rate: 100, features: orb}\n"), HasSubstr("applies to camera sensors only (this sensor is imu)"));
  config.sensors[1].features = FeatureSelection{"orb", "x.pth"};
  EXPECT_THAT(validate(config).error().message, HasSubstr("sensors.camera_rear.features: ORB takes no model"));
}

// fusion.vision.detector: a type name or a block; round trips; bad values named.
TEST(FusionConfig, VisionDetectorChoosesTheSessionsObjectDetector) {
  const std::string sensors = "  sensors:\n    camera: {rate: 10}\n";
  EXPECT_FALSE(parse_fusion_config("fusion:\n" + sensors, "fusion.yaml").value().vision.detector.enabled());  // none by default
  EXPECT_EQ(parse_fusion_config("fusion:\n  vision: {detector: nanodet}\n" + sensors, "fusion.yaml").value().vision.detector,
            (DetectorSelection{"nanodet", "", 0.35}));
  const FusionConfig config =
      parse_fusion_config("fusion:\n  vision:\n    detector: {type: nanodet, model: m/nanodet.json, score_threshold: 0.5}\n" + sensors, "fusion.yaml").value();
  EXPECT_EQ(config.vision.detector, (DetectorSelection{"nanodet", "m/nanodet.json", 0.5}));
  EXPECT_EQ(parse_fusion_config(to_yaml(config), "fusion.yaml").value().vision.detector, config.vision.detector);
  EXPECT_THAT(error_of("fusion:\n  vision: {detector: yolo}\n" + sensors), HasSubstr("expected none or nanodet, got 'yolo'"));
  EXPECT_THAT(error_of("fusion:\n  vision: {detector: {type: nanodet, score_threshold: 1.5}}\n" + sensors), HasSubstr("score_threshold: 1.5 outside (0, 1)"));
  EXPECT_THAT(error_of("fusion:\n  vision: {detector: {model: x.json}}\n" + sensors), HasSubstr("model: given, but the type is none"));
  EXPECT_THAT(error_of("fusion:\n  vision: {detector: {type: nanodet, threshold: 0.5}}\n" + sensors), HasSubstr("threshold"));
}

TEST(FusionConfig, SaveRefusesAnInvalidConfigAndKeepsTheOldFile) {
  const std::filesystem::path path = std::filesystem::temp_directory_path() / "hanzo_fusion_config_keep.yaml";
  FusionConfig config = load_fusion_config("examples/fusion.yaml").value();
  ASSERT_TRUE(save_fusion_config(config, path.string()).ok());
  config.sensors[1].rate_hz = -1.0;
  const Status status = save_fusion_config(config, path.string());
  ASSERT_FALSE(status.ok());
  EXPECT_EQ(status.error().field, "sensors.lidar.rate");
  EXPECT_EQ(load_fusion_config(path.string()).value().sensors[1].rate_hz, 10.0);
  std::filesystem::remove(path);
}

TEST(FusionConfig, FusionOptionsAreCheckedPerModality) {
  const auto error_of = [](const std::string& sensor_yaml) {
    const Result<FusionConfig> config =
        parse_fusion_config("fusion:\n  sensors:\n" + sensor_yaml, "fusion.yaml");
    return config.ok() ? std::string("ok") : config.error().message;
  };
  EXPECT_EQ(error_of("    imu: {rate: 100, use_orientation: [roll, yaw], timeout: 0.2}\n"), "ok");
  EXPECT_EQ(error_of("    gnss: {rate: 5, use_orientation: [roll]}\n"),
            "fusion.yaml:3: sensors.gnss.use_orientation: applies to imu sensors only (this sensor is gnss)");
  EXPECT_EQ(error_of("    imu: {rate: 100, use_orientation: [heading]}\n"),
            "fusion.yaml:3: sensors.imu.use_orientation[0]: expected roll, pitch or yaw, got 'heading'");
  EXPECT_EQ(error_of("    wheels: {rate: 50, speed_noise: 0}\n"), "fusion.yaml:3: sensors.wheels.speed_noise: expected a standard deviation > 0");
  EXPECT_EQ(error_of("    gnss: {rate: 5, min_fix: GOOD}\n"),
            "fusion.yaml:3: sensors.gnss.min_fix: expected FIX_2D, FIX_3D, RTK_FLOAT or RTK_FIXED, got 'GOOD'");
  const Result<FusionConfig> frontend = parse_fusion_config("fusion:\n  frontend:\n    gate_probability: 1.5\n", "fusion.yaml");
  ASSERT_FALSE(frontend.ok());
  EXPECT_EQ(frontend.error().message, "fusion.yaml:3: frontend.gate_probability: expected a probability in (0, 1], got 1.5");
}

}  // namespace
}  // namespace hanzo::fusion::config
